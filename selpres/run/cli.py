"""What the command line prints: a stage's line, a finished job's table, and Hydra's own refusals in one line.

Hydra refuses a command line before any job starts (an unknown key, a group option that has no file, a value of the
wrong type, an override it cannot parse) in 6 to 20 lines of its own; :func:`hydra_line` says the same in the one
line selpres's refusals use: the key, the value and what is allowed (:mod:`selpres.run.main` prints it, exit 2;
``HYDRA_FULL_ERROR=1`` prints Hydra's whole text first). Light on purpose: ``--help`` imports it, not torch.
"""

from __future__ import annotations

import difflib
import logging
import math
import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from selpres.run.problem import Problem

log = logging.getLogger("selpres")
GRAMMAR = "https://hydra.cc/docs/advanced/override_grammar/basic/"


# ------------------------------------------------------------------------------ Hydra's refusals in one line
def hydra_line(e: BaseException, overrides: list[str]) -> str | None:
    """One line for Hydra's (or omegaconf's) refusal ``e`` of the command line ``overrides``; None if ``e`` is
    something else (a bug, not a refusal)."""
    from hydra.errors import ConfigCompositionException, MissingConfigException, OverrideParseException
    from omegaconf.errors import OmegaConfBaseException

    text = str(e).strip()
    if isinstance(e, OverrideParseException):
        bad = _unparsable(overrides)
        return f"cannot read the override {bad!r}: {text.splitlines()[0]} (the override grammar: {GRAMMAR})"
    if isinstance(e, MissingConfigException) or "Available options in" in text:
        return _no_such_option(text, overrides)
    cause = e.__cause__ if isinstance(e, ConfigCompositionException) else e
    if isinstance(cause, OmegaConfBaseException):
        key = str(getattr(cause, "full_key", "") or "")
        given = _given(key, overrides, getattr(cause, "value", None))
        if type(cause).__name__ in ("ConfigKeyError", "ConfigAttributeError") and key:
            return _no_such_key(key, given, overrides)
        if type(cause).__name__ == "ValidationError" and key:
            value = given.partition("=")[2] if given else getattr(cause, "value", None)
            return f"{key}={value!r} is not allowed: expected {_expected(cause)}"
        if type(cause).__name__ == "MissingMandatoryValue" and key:
            group, dot, _ = key.partition(".")
            option = f", or a {group}= option that sets it" if dot else ""  # a top-level key belongs to no group
            return f"{key} has no value (???): expected {key}=<value>{option}"
        msg = str(getattr(cause, "msg", "") or text).strip().splitlines()[0]
        return f"{key}: {msg}" if key and key not in msg else msg
    if isinstance(e, ConfigCompositionException):
        return " ".join(line.strip() for line in text.splitlines() if line.strip())
    return None


def _key_of(override: str) -> str:
    return override.lstrip("+~").partition("=")[0]


def _given(key: str, overrides: list[str], value) -> str | None:
    """The override of ``key`` Hydra refused: the one with the refused value, else the last (it wins)."""
    given = [o for o in overrides if _key_of(o) == key]
    return next((o for o in given if o.partition("=")[2] == str(value)), given[-1] if given else None)


def _unparsable(overrides: list[str]) -> str:
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    for o in overrides:
        try:
            parser.parse_overrides([o])
        except Exception:
            return o
    return " ".join(overrides)


def _no_such_option(text: str, overrides: list[str]) -> str:
    """A group option with no config file: ``topology=6-99-2`` -> the group's options."""
    found = re.search(r"Could not (?:find|load) '([^']+)'", text)
    path = found.group(1) if found else ""
    group, _, option = path.rpartition("/")
    options = []
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("Available options in"):
            for x in lines[i + 1 :]:
                if not x.startswith(("\t", " ")) or not x.strip():
                    break
                options.append(x.strip())
            break
    if not group:
        return text.splitlines()[0]
    allowed = f"one of {', '.join(options)}" if options else f"an option of the config group {group}/"
    return f"{group}={option} is not allowed: expected {allowed} (the files of configs/{group}/)"


def _no_such_key(key: str, given: str | None, overrides: list[str]) -> str:
    """An override of a key the composed config does not have: the keys its node has, the nearest first."""
    parent, _, name = key.rpartition(".")
    keys = _keys_at(parent, [o for o in overrides if o != given])
    near = difflib.get_close_matches(name, keys, n=1)
    where = parent or "the top level"
    allowed = f"one of the keys of {where}: {', '.join(keys)}" if keys else f"a key of {where}"
    hint = f" (did you mean {parent + '.' if parent else ''}{near[0]}?)" if near else ""
    return f"{given or key} is not allowed: {key} is not a key; expected {allowed}{hint}"


def _keys_at(parent: str, overrides: list[str]) -> list[str]:
    """The keys of the node ``parent`` of the config as the other overrides compose it (none where they fail)."""
    from omegaconf import DictConfig, OmegaConf

    from selpres.run.config import CONFIG_DIR, compose_train

    for tries in (overrides, []):
        try:
            cfg = compose_train(CONFIG_DIR, tries)
        except Exception:
            continue
        node = OmegaConf.select(cfg, parent) if parent else cfg
        return sorted(str(k) for k in node.keys()) if isinstance(node, DictConfig) else []
    return []


def _expected(cause) -> str:
    """What a value of the wrong type should have been, from omegaconf's message."""
    msg = str(getattr(cause, "msg", cause))
    kinds = {"Integer": "a whole number", "Float": "a number", "Boolean": "true or false", "String": "a string"}
    m = re.search(r"could not be converted to (\w+)", msg)
    if m:
        return kinds.get(m.group(1), m.group(1))
    m = re.search(r"expected one of \[([^\]]*)\]", msg)
    if m:
        return f"one of {m.group(1)}"
    return msg.splitlines()[0]


# ------------------------------------------------------------------------------ what gets printed
def _mean(vals) -> float:
    f = [v for v in vals if v is not None]
    return sum(f) / len(f) if f else math.nan


def print_stage(rec: dict, prob: Problem) -> None:
    """One line at the end of each stage: size, epoch, cost so far and the errors (mean over replicas)."""
    R = len(prob.seeds)
    held = f"  held-out RMS {_mean(rec['heldout_rms_nm']):.4f} Nm" if rec["heldout_rms_nm"] else ""
    log.info(
        f"stage {rec['stage'] + 1}/{len(prob.schedule.stages)}  n_i={rec['size']:5d}  epoch {rec['epoch'] + 1:4d}  "
        f"presentations {rec['presentations']:7d}  train MSE {_mean(rec['train_mse']):.3e}  "
        f"test-10 RMS {_mean(rec['test10_rms_nm']):.4f} Nm{held}" + (f"  (mean of {R} replicas)" if R > 1 else "")
    )


def summary_table(results: dict) -> str:
    """The short table printed at the end of a job."""
    s, sch = results["summary"], results["schedule"]

    def fmt(key):
        m = s[key]
        if m["mean"] is None:
            return "n/a"
        return f"{m['mean']:.4f}" + (f" ± {m['std']:.4f}" if m["std"] is not None else "")

    engine, fallback = results["engine"], results.get("engine_fallback")
    if results.get("engine_requested", engine) != engine:
        engine += f" (requested {results['engine_requested']}" + (f"; fell back: {fallback}" if fallback else "") + ")"
    wall = results["wall_seconds"]
    rows = [
        ("schedule", f"{sch['name']} (p={sch['p']}, sizes {sch['sizes']}, epochs {sch['epochs']})"),
        ("topology", results["topology"]),
        (
            "replicas",
            f"{results['replicas']} (seeds {results['seeds'][0]}..{results['seeds'][-1]}), "
            f"{results['diverged_replicas']} diverged",
        ),
        (
            "cost T/t",
            f"{_count(sch['presentations'])} presentations  (T_con/t at equal epochs "
            f"{_count(sch['conventional_presentations'])}; ratio {sch['cost_ratio']:.3f})"
            + (
                f" + {_count(results['selection_presentations'])} charged for choosing A_i"
                if results.get("selection_presentations")
                else ""
            ),
        ),
        ("engine", engine),
        ("wall time", f"{wall['total']:.2f} s total, {wall['train']:.2f} s in updates"),
        ("test-10 RMS", f"{fmt('test10_rms_nm_overall')} Nm   {fmt('test10_rms_scaled_overall')} scaled"),
        ("held-out RMS", f"{fmt('heldout_rms_nm_overall')} Nm   {fmt('heldout_rms_scaled_overall')} scaled"),
    ]
    if "heldout_rms_nmse_overall" in s and results.get("floor"):  # selpres.run.floor
        base = results["floor"]["heldout"]["nm"]["overall"]
        rows.append(("held-out nMSE", f"{fmt('heldout_rms_nmse_overall')}   (predicting the mean: {base:.4f} Nm)"))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)


def _count(x: float) -> str:
    """Presentations as the summary says them: whole ones with thousands separators, a mean over replicas to 0.1."""
    return f"{int(x):,}" if float(x).is_integer() else f"{x:,.1f}"
