"""Issue 39: disk faults beyond a single job's folder: a job of a sweep (it fails alone, the same sweep command
resumes it), Hydra's own record of a sweep's job, and the report's files (the fault-injection layer:
tests/test_faults.py)."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
from test_faults import Disk, Ran, _is, clean_numbers, final_name, newest_epoch, train, whole

from conftest import numbers


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return clean_numbers(tmp_path_factory)


# ------------------------------------------------------------------------------------------------ a sweep
def sweep(folder: Path, *extra: str) -> Ran:
    """``python train.py -m JOB... seed=0,1`` into ``folder`` (Hydra's basic launcher: its jobs in this process)."""
    return train(folder, "-m", f"hydra.sweep.dir={folder}", "hydra.sweep.subdir=seed${seed}", "seed=0,1", *extra)


def test_a_fault_in_a_sweeps_job_fails_that_job_in_one_line_and_the_same_sweep_resumes_it(clean, tmp_path):
    """The disk fills while the first job writes its third checkpoint: that job fails in one line naming the file
    (Hydra's compact error, exit 1), the other job runs to its end; the same sweep command resumes the failed job
    from its last checkpoint to the numbers of a run that met no fault, and finds the other done."""
    folder = tmp_path / "sweep"
    disk = Disk("ENOSPC", lambda n: n.startswith("checkpoint"), skip=2, budget=4096)  # the first job's folder
    with disk.mounted():
        ran = sweep(folder)
    assert ran.code == 1 and disk.fired
    failed, other = folder / "seed0", folder / "seed1"
    assert Path(disk.fired[0]).parent == failed
    lines = [ln for ln in ran.err if str(failed / final_name(disk.fired[0])) in ln]
    assert lines and all(os.strerror(errno.ENOSPC) in ln for ln in lines) and "Traceback" not in "\n".join(ran.err)
    assert json.loads((other / "results.json").read_text())["status"] == "complete"
    assert newest_epoch(failed) == disk.newest is not None
    whole(failed)
    again = sweep(folder)
    assert again.code == 0, again.err
    res = json.loads((failed / "results.json").read_text())
    assert res["resumed_from_epoch"] == disk.newest and numbers(res) == clean


_HYDRA_RECORD = """
import json, sys
from pathlib import Path
sys.path.insert(0, sys.argv[2])
import test_faults as T, test_faults_sweeps as S
disk = T.Disk("ENOSPC", T._is("config.yaml"), skip=1)  # the second job's record
with disk.mounted():
    ran = S.sweep(Path(sys.argv[1]))
print(json.dumps({"code": ran.code, "err": ran.err, "fired": disk.fired}))
"""


@pytest.mark.slow
def test_a_fault_while_hydra_writes_a_sweep_jobs_record_is_one_line(tmp_path):
    """Hydra's record of a job is written by the job once it holds its folder (selpres.run.job), a sweep's job as a
    single run: its failure fails that job in one line. In a process of its own, as a user's sweep runs."""
    from conftest import run_python

    folder = tmp_path / "sweep"
    done = run_python("-c", _HYDRA_RECORD, str(folder), str(Path(__file__).parent))
    ran = json.loads(done.stdout.strip().splitlines()[-1])
    assert ran["fired"] and "Traceback" not in "\n".join(ran["err"])
    assert [ln for ln in ran["err"] if os.strerror(errno.ENOSPC) in ln and "config.yaml" in ln] == ran["err"][-1:]
    assert json.loads((folder / "seed0" / "results.json").read_text())["status"] == "complete"


# ------------------------------------------------------------------------------------- the report's files
def test_a_fault_while_the_report_is_written_is_one_line_and_the_results_stay(tmp_path, capsys):
    """selpres-report into a full disk: one line naming the file and the cause, exit 2; the sweep's folders are
    as they were, and the report written again once there is room is the report of a disk that never failed."""
    from selpres.report.__main__ import main as report

    sweep = tmp_path / "sweep"
    for seed in (0, 1):
        assert train(sweep / f"seed{seed}", f"seed={seed}").code == 0
    before = {p: p.read_bytes() for p in sweep.rglob("*") if p.is_file()}
    assert report([str(sweep), "--out", str(tmp_path / "good")]) == 0
    capsys.readouterr()
    for name in ("report.md", "runs.csv"):
        out = tmp_path / f"bad-{name}"
        disk = Disk("ENOSPC", _is(name))
        with disk.mounted():
            code = report([str(sweep), "--out", str(out)])
        err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
        assert code == 2 and disk.fired, err
        assert len(err) == 1, err
        (line,) = err
        assert str(out / name) in line and os.strerror(errno.ENOSPC) in line
        assert not list(out.glob(".*.tmp")) and not (out / "report.md").exists()
        assert report([str(sweep), "--out", str(out)]) == 0
        capsys.readouterr()
        assert (out / "report.md").read_text() == (tmp_path / "good" / "report.md").read_text().replace(
            str(tmp_path / "good"), str(out)
        )
    assert {p: p.read_bytes() for p in sweep.rglob("*") if p.is_file()} == before
