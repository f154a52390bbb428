"""The Hydra Optuna sweeper, searching schedules by the few numbers of ``selpres.presentation.search``.

``configs/experiment/search.yaml`` sets ``hydra.sweeper._target_`` to :class:`ShapedScheduleSweeper`. Optuna
samples the search numbers (``search_p``, ``search_first``, ``search_growth``, ``search_tilt``; the budget
``search_budget`` is fixed) like any sweeper parameter and stores them in the study; before each trial is
launched they are replaced by the ``schedule.sizes / epochs / budget`` overrides they stand for, so every
job is an ordinary selpres job (its folder, results.json, TensorBoard, report). It needs
``hydra-optuna-sweeper==1.3.0`` (and ``sqlalchemy<2`` for the SQLite study) and hooks that version's
``OptunaSweeperImpl._configure_trials``, which builds each trial's overrides.

Resuming: the study lives in SQLite (``hydra.sweeper.storage``) and ``n_trials`` counts the study's
finished trials, earlier runs included, so the same command after an interruption runs only what is
missing (the plugin alone would run ``n_trials`` more each time), with the sampler seeded by its seed plus
the finished trials (the same seed would propose the same first points again); a job interrupted
mid-training resumes from its checkpoint in its own folder, and a schedule proposed twice is found done.
A trial whose schedule its job refuses (rounding merged two stage sizes) fails alone: Optuna records it
as failed, and ``max_failure_rate: 1.0`` keeps the study going.

At the end the confirmation of the best trial and of the best trial of each other order
(``selpres.presentation.search.confirmation_commands``: each schedule on fresh seeds and the held-out set, beside
conventional training stopped at its total cost) is logged and written to ``confirm.sh`` in the sweep
folder: ``bash outputs/sweeps/search/confirm.sh``. Several are confirmed because the validation RMS of 10
search seeds is noisy and the best of many trials is biased low; the report's ``--holm`` adjusts for them.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from hydra.types import HydraContext, TaskFunction
from hydra.utils import instantiate
from hydra_plugins.hydra_optuna_sweeper.optuna_sweeper import OptunaSweeper
from omegaconf import DictConfig

# Hydra imports this module at every start (plugin discovery), so Optuna (with scipy and cmaes, ~3 s here) and
# selpres (torch) are imported only once the sweeper is used.

log = logging.getLogger("selpres")


class ShapedScheduleSweeper(OptunaSweeper):
    """Optuna over (p, first, growth, tilt) at a fixed budget, each trial run as its schedule's overrides."""

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        import optuna

        from selpres.data.task import load_task
        from selpres.presentation.search import SEARCH_KEYS, confirmation_commands, schedule_overrides
        from selpres.run.specs import task_specs

        super().setup(hydra_context=hydra_context, task_function=task_function, config=config)
        impl = self.sweeper
        n = load_task(*task_specs(config)).n
        sweep_order, cost = config.schedule.order, config.schedule.selection_cost
        configure = impl._configure_trials

        def translated(trials, distributions, fixed):
            out = []
            for overrides in configure(trials, distributions, fixed):
                raw = dict(o.split("=", 1) for o in overrides if o.split("=", 1)[0] in SEARCH_KEYS)
                missing = [k for k in SEARCH_KEYS if k not in raw]
                if missing:
                    raise ValueError(f"hydra.sweeper.params must give {list(SEARCH_KEYS)}; missing {missing}")
                rest = [o for o in overrides if o.split("=", 1)[0] not in SEARCH_KEYS]
                swept = [o.split("=", 1)[1] for o in rest if o.startswith("schedule.order=")]
                order = swept[0] if swept else sweep_order
                out.append((*rest, *schedule_overrides(raw, n, order, cost)))
            return out

        impl._configure_trials = translated
        self._confirm = lambda best: confirmation_commands(best, n, cost)
        self._order = sweep_order
        done = _finished_trials(impl.storage, impl.study_name)
        if done:
            log.info(
                "study %s has %d finished trials; running %d more", impl.study_name, done, max(0, impl.n_trials - done)
            )
            impl.n_trials = max(0, impl.n_trials - done)
            seed = config.hydra.sweeper.sampler.get("seed")
            if seed is not None and isinstance(impl.sampler, optuna.samplers.BaseSampler):
                # a seeded sampler would propose the same first points again: seed + finished trials
                impl.sampler = instantiate(config.hydra.sweeper.sampler, seed=seed + done)
                log.info(
                    "sampler seed %d (hydra.sweeper.sampler.seed %d + %d finished trials)", seed + done, seed, done
                )

    def sweep(self, arguments: list[str]) -> None:
        """The study's trials, then the commands that confirm the best schedule of the study and the best of
        each order, logged and written to ``confirm.sh`` in the sweep folder."""
        import optuna

        super().sweep(arguments)
        impl = self.sweeper
        if impl.storage is None:
            return
        study = optuna.load_study(study_name=impl.study_name, storage=impl.storage)
        best = best_trials(study, self._order)
        commands = self._confirm([(raw, order) for _, raw, order in best])
        notes = [f"# {order}: trial {t.number}, validation RMS {t.value:.6f} Nm" for t, _, order in best]
        script = Path(impl.config.hydra.sweep.dir) / "confirm.sh"
        script.write_text(
            f"# study {impl.study_name}: the best trial, then the best of each other order, "
            "to confirm on fresh seeds and the held-out set\n"
            + "\n".join(notes)
            + "\nset -e\n"
            + "\n".join(commands)
            + "\n"
        )
        log.info(
            "best schedules (%s); confirm them on fresh seeds and the held-out set against "
            "compute-matched conventional training (also in %s):\n%s",
            "; ".join(n[2:] for n in notes),
            script,
            "\n".join(commands),
        )


def best_trials(study, default_order: str) -> list[tuple]:
    """[(trial, search numbers, order)]: the study's best complete trial, then the best of every other
    order tried, by validation RMS."""
    import optuna

    complete = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    done = sorted(complete, key=lambda t: (t.value, t.number))
    out: dict[str, tuple] = {}
    for t in done:
        raw = {**t.user_attrs, **t.params}
        out.setdefault(raw.get("schedule.order", default_order), (t, raw))
    return [(t, raw, order) for order, (t, raw) in out.items()]


def _finished_trials(storage, study_name) -> int:
    """Complete or failed trials of the stored study (0 if there is none yet)."""
    if storage is None or study_name is None:
        return 0
    import optuna

    try:
        study = optuna.load_study(study_name=study_name, storage=storage)
    except KeyError:  # no such study yet
        return 0
    except Exception as e:  # not a database, cut, another program's: one line, exit 2, the file left as it is
        why = str(e).splitlines()[0][:200]
        print(f"error: hydra.sweeper.storage={storage} cannot be read ({type(e).__name__}: {why}); move the file "
              "aside to start the study afresh, or name another storage", file=sys.stderr)  # fmt: skip
        sys.exit(2)
    states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.FAIL)
    return sum(t.state in states for t in study.get_trials(deepcopy=False))
