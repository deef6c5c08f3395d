"""Fault injection: what a batch promises when runs crash, fail, or the batch is stopped.

Every check ends by comparing with a clean batch of the same runs: the same summaries
(timings aside) and the same index, one row per run.
"""

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from harm_calibration.cli import main
from mujoco_world.experiments.batch import (
    BatchInterrupted,
    RunTask,
    check_unique,
    comparison_table,
    run_batch,
)
from mujoco_world.experiments.workers import describe_exit
from mujoco_world.loop.summary import RunSummary
from mujoco_world.storage.run_index import read_index
from mujoco_world.storage.run_record import RunRecord, read_record
from tests.harm_calibration.cli.conftest import write_scenario
from tests.mujoco_world.experiments import faults

REPO = Path(__file__).resolve().parents[3]
faults.register()


@pytest.fixture(autouse=True)
def ctrl_c_raises():
    """Ctrl-C as at a terminal, also when pytest runs where SIGINT is ignored.

    A background job of a non-interactive shell (``python -m pytest &``) starts with
    SIGINT ignored, and so would every ``etp demo`` these tests start: a Python handler
    here is reset to the default on exec, so the children get Python's own again.
    """
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)


def _tasks(scenario, out, planners, seeds=(0,)):
    return [RunTask(scenario, p, s, str(out), record=False) for p in planners for s in seeds]


def _summaries(out):
    """run id -> summary without timings, from the records of ``out``."""
    return {
        p.parent.name: read_record(p).summary.comparable_dict()
        for p in sorted(Path(out).glob("*/summary.json"))
    }


def _index_lines(out):
    lines = (Path(out) / "index.jsonl").read_text().splitlines()
    return [json.loads(line) for line in lines if line.strip()]


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    return write_scenario(tmp_path_factory.mktemp("scenario"), duration=1.0)


@pytest.fixture(scope="module")
def clean(scenario, tmp_path_factory):
    """A clean batch: four slow runs (0.1 s of real time per planning cycle), in this process."""
    out = tmp_path_factory.mktemp("clean")
    tasks = _tasks(scenario, out, ["fault_slow"], seeds=range(4))
    results = run_batch(tasks, workers=1, progress=False)
    assert all(r.record.summary.outcome in ("goal", "timeout") for r in results)
    return out


def test_a_crashing_worker_is_blamed_on_its_own_run_and_the_batch_goes_on(scenario, tmp_path):
    planners = ["keep_lane", "fault_segv", "fault_raise", "fault_kill"]
    tasks = [RunTask(scenario, p, 0, str(tmp_path)) for p in planners]  # with recordings
    results = run_batch(tasks, workers=2, progress=False, worker_initializer=faults.register)
    by_planner = {r.record.summary.planner: r.record.summary for r in results}
    assert by_planner["fault_segv"].reason == "worker process died (SIGSEGV)"
    assert by_planner["fault_kill"].reason == "worker process died (SIGKILL)"
    assert by_planner["fault_raise"].reason.startswith("planner raised RuntimeError at t = 0.000 s")
    for name in ("fault_segv", "fault_kill", "fault_raise"):
        assert by_planner[name].outcome == "failed"
    assert by_planner["keep_lane"].outcome in ("goal", "timeout")
    # The stored records and the index say the same, one row per run, in task order.
    for task, result in zip(tasks, results, strict=True):
        assert read_record(task.record_path).summary.reason == result.record.summary.reason
    rows = _index_lines(tmp_path)
    assert [r["run_id"] for r in rows] == [t.run_id for t in tasks]
    assert [r["outcome"] for r in rows] == [r.record.summary.outcome for r in results]
    # A crashed run keeps the recording its worker left, named as partial and readable.
    kept = results[1].record.recording
    assert kept == str(tasks[1].run_dir / "recording.partial.rrd")
    assert any(True for _ in RrdReader(kept).stream().to_chunks())
    assert results[0].record.recording == str(tasks[0].run_dir / "recording.rrd")
    assert not (tasks[0].run_dir / "recording.partial.rrd").exists()
    # A crashed run's missing risk is no number, and the healthy runs equal a run in this process.
    assert rows[1]["max_risk"] == {"ego": "nan", "third_party": "nan", "vulnerable": "nan"}
    alone = tmp_path / "alone"
    run_batch(_tasks(scenario, alone, ["keep_lane"]), workers=1, progress=False)
    (run, summary), *_ = _summaries(alone).items()
    assert _summaries(tmp_path)[run] == summary


def test_a_failed_run_is_resumed_as_failed_and_retried_on_request(scenario, tmp_path, monkeypatch):
    flag = tmp_path / "flaky"
    flag.touch()
    monkeypatch.setenv(faults.FLAKY_FLAG, str(flag))
    out = tmp_path / "out"
    tasks = _tasks(scenario, out, ["fault_flaky", "keep_lane"])
    first = run_batch(tasks, workers=1, progress=False)
    assert [r.record.summary.outcome for r in first][0] == "failed"
    flag.unlink()  # the cause is gone
    again = run_batch(tasks, workers=1, progress=False)
    assert all(r.resumed for r in again) and again[0].record.summary.outcome == "failed"
    retried = run_batch(tasks, workers=1, progress=False, retry_failed=True)
    assert [r.resumed for r in retried] == [False, True]
    assert retried[0].record.summary.outcome in ("goal", "timeout")
    assert read_record(tasks[0].record_path).summary.outcome == retried[0].record.summary.outcome
    rows = _index_lines(out)  # three batches, one row per run: the latest
    assert [(r["run_id"], r["outcome"]) for r in rows] == [
        (t.run_id, r.record.summary.outcome) for t, r in zip(tasks, retried, strict=True)
    ]


def test_runs_that_share_a_folder_are_refused(scenario, tmp_path):
    same = str(Path(scenario).parent / ".." / Path(scenario).parent.name / Path(scenario).name)
    tasks = [RunTask(scenario, "keep_lane", 0, str(tmp_path)), RunTask(same, "keep_lane", 0, str(tmp_path))]
    with pytest.raises(ValueError, match="are one run"):
        check_unique(tasks)
    with pytest.raises(ValueError, match="are one run"):
        run_batch(tasks, workers=1, progress=False)
    assert not (tmp_path / "index.jsonl").exists()


def test_serial_batch_interrupted_keeps_what_finished(scenario, tmp_path):
    """workers = 1: Ctrl-C inside a run closes it as failed; the index lists what exists."""
    tasks = _tasks(scenario, tmp_path, ["keep_lane", "fault_slow", "keep_lane"], seeds=(0,))
    tasks[2] = RunTask(scenario, "keep_lane", 1, str(tmp_path), record=False)

    armed = []

    def interrupt_soon(result):
        if not armed:  # once: Ctrl-C 0.3 s into the second run
            armed.append(signal.setitimer(signal.ITIMER_REAL, 0.3))

    previous = signal.signal(signal.SIGALRM, lambda *_: os.kill(os.getpid(), signal.SIGINT))
    try:
        with pytest.raises(BatchInterrupted) as stop:
            run_batch(tasks, workers=1, progress=False, on_result=interrupt_soon)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    done, closed = stop.value.results
    assert stop.value.total == 3
    assert done.record.summary.outcome in ("goal", "timeout") and closed.record.summary.outcome == "failed"
    assert closed.record.summary.reason.startswith("interrupted at t = ")
    assert not tasks[1].record_path.exists()  # no record: a rerun runs it again
    assert [r.run_id for r in read_index(tmp_path)] == [tasks[0].run_id, tasks[1].run_id]


# --------------------------------------------------------------------------- signals to `etp demo`


def _demo_args(scenario, out, workers=2):
    return [
        "demo",
        "--scenarios",
        scenario,
        "--planners",
        "fault_slow",
        "--seeds",
        "0,1,2,3",
        "--no-record",
        "--no-progress",
        "--workers",
        str(workers),
        "--out",
        str(out),
    ]


def _demo(scenario, out):
    """Start ``etp demo`` (faulty planners registered) in a new process group."""
    code = "from tests.mujoco_world.experiments.faults import demo_main; demo_main()"
    command = [sys.executable, "-c", code, *_demo_args(scenario, out)]
    return subprocess.Popen(
        command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )


def _alive_in_group(pgid):
    """Pids of living (not zombie) processes of process group ``pgid`` (Linux /proc)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            alive.append(int(stat.parent.name))
    return alive


def _group_ends(pgid, timeout=10.0):
    """True once no process of group ``pgid`` lives (the resource tracker leaves a moment after)."""
    deadline = time.monotonic() + timeout
    while _alive_in_group(pgid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return _alive_in_group(pgid) == []


def _wait_for_rows(out, n, process, timeout=120.0):
    index = Path(out) / "index.jsonl"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert process.poll() is None, process.communicate()
        if index.is_file() and len(index.read_text().splitlines()) >= n:
            return
        time.sleep(0.05)
    raise AssertionError(f"no {n} index rows in {timeout} s")


def _rerun_equals_clean(scenario, out, clean, capsys):
    """Rerun the batch (here, one worker: the same runs) and compare with the clean batch."""
    capsys.readouterr()
    assert main(_demo_args(scenario, out, workers=1)) == 0
    assert "resumed from existing records" in capsys.readouterr().out
    assert _summaries(out) == _summaries(clean)
    assert _index_lines(out) == _index_lines(clean)


def test_an_atomic_write_that_fails_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    from mujoco_world.storage import run_record

    path = run_record.write_json(tmp_path / "summary.json", {"old": 1})

    def no_space(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(run_record.os, "fsync", no_space)
    with pytest.raises(OSError, match="No space left"):
        run_record.write_json(path, {"new": 2})
    assert json.loads(path.read_text()) == {"old": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]  # no summary.json.tmp


def test_a_full_disk_stops_the_batch_with_a_message_and_keeps_what_was_written(
    scenario, tmp_path, monkeypatch, capsys
):
    from mujoco_world.storage import run_record

    out = tmp_path / "out"
    args = _demo_args(scenario, out, workers=1)
    args[args.index("0,1,2,3")] = "0,1"
    real = run_record.write_text
    records = []

    def full_disk(path, text):
        if Path(path).name == "summary.json":
            records.append(path)
            if len(records) > 1:  # the first record fits, then the disk is full
                raise OSError(errno.ENOSPC, "No space left on device", str(path) + ".tmp")
        return real(path, text)

    monkeypatch.setattr(run_record, "write_text", full_disk)
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"etp demo: error: {records[1]}.tmp: No space left on device" in err and "Traceback" not in err
    records = sorted(out.glob("*/summary.json"))
    assert len(records) == 1 and read_record(records[0]).summary.outcome in ("goal", "timeout")
    monkeypatch.setattr(run_record, "write_text", real)
    assert main(args) == 0  # space again: the rerun resumes the first run, runs the second
    assert "1 resumed" in capsys.readouterr().out
    assert len(read_index(out)) == 2


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc and process groups")
@pytest.mark.parametrize("to", ["group", pytest.param("parent", marks=pytest.mark.slow)])
def test_ctrl_c_stops_the_batch_at_once_and_a_rerun_resumes(scenario, clean, tmp_path, capsys, to):
    """Ctrl-C (to the whole group, or to the parent only): exit 130 soon, no process left."""
    out = tmp_path / "out"
    process = _demo(scenario, out)
    _wait_for_rows(out, 1, process)  # one run finished, others in flight
    sent = time.monotonic()
    if to == "group":
        os.killpg(process.pid, signal.SIGINT)
    else:
        os.kill(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=60)
    took = time.monotonic() - sent
    assert process.returncode == 130, err
    assert took < 15.0  # runs close within a planning cycle; generous for a loaded machine
    assert "Traceback" not in err and "interrupted:" in err
    assert _group_ends(process.pid)
    aggregate = json.loads((out / "aggregate.json").read_text())
    reasons = [r["reason"] for r in aggregate["runs"]]
    # Every run the batch started or handed to a worker is listed; one handed over just
    # before the Ctrl-C is "interrupted before the run started", so all four may be.
    assert 2 <= len(reasons) <= 4 and any(r.startswith("interrupted") for r in reasons)
    rows = _index_lines(out)
    assert len({r["run_id"] for r in rows}) == len(rows) == len(reasons)
    # The rerun resumes: the finished runs are read, the others run; the result is the clean one.
    _rerun_equals_clean(scenario, out, clean, capsys)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc and process groups")
def test_kill_9_leaves_no_worker_and_a_rerun_gives_one_row_per_run(scenario, clean, tmp_path, capsys):
    out = tmp_path / "out"
    process = _demo(scenario, out)
    _wait_for_rows(out, 1, process)
    os.kill(process.pid, signal.SIGKILL)
    process.communicate(timeout=30)
    assert _group_ends(process.pid)  # the workers died with the parent
    _rerun_equals_clean(scenario, out, clean, capsys)


class _PipeThatIsInterrupted:
    """A worker's pipe end that takes the message, then a Ctrl-C arrives (SIGINT to this process)."""

    def __init__(self, answer=None):
        self.sent, self.answer = [], answer

    def send(self, message):
        self.sent.append(message)
        os.kill(os.getpid(), signal.SIGINT)

    def poll(self):
        return True

    def recv(self):
        os.kill(os.getpid(), signal.SIGINT)
        return self.answer


def test_a_ctrl_c_while_a_job_is_handed_over_leaves_the_parent_knowing_it():
    """The CI flake of stop 18: a job sent but not noted (or an answer received but not
    handed on) made the worker index a run the parent's aggregate did not list."""
    from mujoco_world.experiments.workers import _Pool, _Worker

    results = []
    pool = _Pool(len, None, lambda key, value: results.append((key, value)), lambda key, why: None)

    class _Alive:
        def is_alive(self):
            return True

    worker = _Worker(process=_Alive(), conn=_PipeThatIsInterrupted())
    pool.workers.append(worker)
    with pytest.raises(KeyboardInterrupt):
        pool.give(worker, ("run-7", "job"))
    assert worker.conn.sent == [("run-7", "job")] and worker.job == ("run-7", "job")

    worker.conn.answer = ("run-7", True, "result", False)
    with pytest.raises(KeyboardInterrupt):
        pool._answer(worker)
    assert results == [("run-7", "result")] and worker.job is None


def test_a_worker_death_is_described_by_its_signal_or_exit_code():
    assert describe_exit(-signal.SIGABRT) == "SIGABRT"
    assert describe_exit(-signal.SIGSEGV) == "SIGSEGV"
    assert describe_exit(3) == "exit code 3"
    assert describe_exit(-200) == "signal 200"


def test_failed_runs_are_counted_but_not_averaged_as_zero():
    ok = RunSummary(
        scenario="s",
        planner="p",
        seed=0,
        outcome="goal",
        reason="goal reached",
        max_risk={"ego": 0.2, "third_party": 0.1, "vulnerable": 0.0},
    )
    failed = RunSummary(scenario="s", planner="p", seed=1, outcome="failed", reason="worker process died")
    table = comparison_table([RunRecord("a", ok), RunRecord("b", failed)])
    totals = table.splitlines()[-1]
    assert "2 runs  goal 1" in totals and "failed 1" in totals
    assert "max risk ego 0.2000 3rd 0.1000 VRU 0.0000" in totals  # not (0.2 + 0) / 2
    only_failed = comparison_table([RunRecord("b", failed)]).splitlines()[-1]
    assert "max risk ego - 3rd - VRU -" in only_failed and "harm ego - " in only_failed
