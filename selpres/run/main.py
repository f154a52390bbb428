"""``selpres-train`` (and a checkout's ``python train.py``, a shim over this): the command, around Hydra.

:func:`main` handles the signals before anything else loads (:mod:`selpres.run.stop`: from then on a Ctrl-C is
recorded and answered, whatever swallows its raise), has Hydra compose the package's configs
(:data:`selpres.run.config.CONFIG_DIR`: the same command composes the same config from a checkout, an editable
install or a wheel, run from any folder) and run :func:`selpres.run.job.run` for each job, and ends the process
as the job's outcome says (:data:`selpres.run.outcomes.OUTCOMES`). Hydra's own refusal of a command line becomes one
line, exit 2 (:func:`selpres.run.cli.hydra_line`; ``HYDRA_FULL_ERROR=1``: Hydra's whole text first). Only Hydra,
omegaconf and the schema load before Hydra parses the command line: torch and the loop load for a job, not for
``--help`` or ``--cfg``.
"""

from __future__ import annotations

import gc
import os
import shlex
import signal
import sys
from pathlib import Path

from selpres.run import stop


def main() -> None:
    """The console script: the signals first, Hydra's main with the job's life as its task, one exit status."""
    stop.install()  # first: a Ctrl-C from here on is recorded and answered (selpres.run.stop)
    before, code = {}, 0
    try:
        import hydra

        from selpres.run import job, orphan
        from selpres.run.config import CONFIG_DIR, retired, unread  # also registers the schema and resolvers

        # before Hydra: its own refusal would not name the new spelling; an unread key before a sweep launches
        refusal = retired(sys.argv[1:]) or unread(sys.argv[1:])
        if refusal is not None:
            sys.exit(_say(f"error: {refusal}", 2))
        job.new_command()
        full = os.environ.get("HYDRA_FULL_ERROR") == "1"
        before = {k: os.environ.get(k) for k in (job.COMMAND, job.FULL_ERROR, "HYDRA_FULL_ERROR", orphan.ENV)}
        os.environ[job.COMMAND] = _as_typed(sys.argv)  # for the line that says how to resume (a sweep's workers too)
        if full:
            os.environ[job.FULL_ERROR] = "1"
        os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises its errors here instead of printing them and exiting 1
        hydra.main(version_base="1.3", config_path=str(CONFIG_DIR), config_name="train")(job.run)()
        if stop.requested() is not None:  # a request whose raise was lost after the job answered (or before it ran)
            code = _say(*_stopped())
    except KeyboardInterrupt:  # while Hydra and the schema load or compose, or as a job said it (then no second line)
        code = _say(*_stopped())
    except Exception as e:
        code = _failed(e, before.get("HYDRA_FULL_ERROR") == "1")
    finally:
        for k, v in before.items():  # the environment as it was (for a caller in the same process)
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        # Everything is written and closed by now; what remains is the interpreter's exit, whose cyclic-garbage
        # passes walk every object torch and Hydra made (0.3-0.5 s of a 2.5 s default run, measured with
        # `python -m selpres_bench.startup`). Frozen objects are skipped by those passes; atexit handlers
        # (logging's flush, weakref finalizers) still run.
        gc.freeze()
    sys.exit(code)


def _failed(e: Exception, full: bool) -> int:
    """An exception out of Hydra: a sweep's jobs that did not finish, a stop's aftermath, or Hydra's refusal."""
    from selpres.run import cli, job

    if isinstance(e, job.SweepJobError):  # each one's line (a worker's: the first, the others are in its log)
        return stop.STATUS[stop.requested()] if stop.requested() else _say("\n".join(job.unfinished() or [str(e)]), 1)
    if stop.requested() is not None:  # an error a stop caused (omegaconf's clean-up replacing the interrupt)
        return _say(*_stopped())
    if full:
        import traceback

        traceback.print_exc()
    line = cli.hydra_line(e, sys.argv[1:])
    return _say(f"error: {line}", 2) if line else _say(f"error: {type(e).__name__}: {e}", 1)


def _stopped() -> tuple[str | None, int]:
    job = sys.modules.get("selpres.run.job")  # not imported (nor re-imported half-way): no job can have started
    if job is None:
        signum = stop.requested() or signal.SIGINT
        name = signal.Signals(signum).name
        return f"stopped by {name} before the job started: nothing was written", stop.STATUS[signum]
    return job.stopped_outside(stop.requested())


def _say(line: str | None, code: int) -> int:
    if line:
        print(line, file=sys.stderr)
    return code


def _as_typed(argv: list[str]) -> str:
    """The command line as the user typed it, for the line that says how to resume."""
    prog = Path(argv[0])
    if prog.name == "train.py":
        head = f"python {argv[0]}"
    elif prog.name == "main.py":  # python -m selpres.run.main
        head = "python -m selpres.run.main"
    else:
        head = prog.name
    return " ".join([head, *map(shlex.quote, argv[1:])])


if __name__ == "__main__":
    main()
