"""SIGINT, SIGTERM, SIGHUP and SIGKILL at random moments: each stop ends in one line with
exit 130 or 143, leaves no temporary file, keeps an earlier archive byte-identical, and
where a checkpoint exists ``--resume`` (the printed command, as given) gives exactly the
uninterrupted result."""

from __future__ import annotations

import contextlib
import random
import signal
import time

import pytest
from faultkit import cli as run_cli
from faultkit import config, copy, one_line, resume_args, same_result, spawn, strays

from designopt.io import archive, writer

CODES = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGHUP: 143}
N_ITERS = 60  # TINY's; chunks of 3 iterations, so 19 boundaries before the end
KILL_POINTS = {"in-process": 0, "child": 0}


def _signal_at(monkeypatch, iteration: int, signum: int) -> None:
    """The CLI's progress bar raises ``signum`` (a real signal, through the CLI's own
    handlers) once ``iteration`` iterations are done (counted from the run's start)."""

    @contextlib.contextmanager
    def bar(total, desc):
        done, sent = [0], []

        def update(n):
            done[0] += n
            if done[0] >= iteration and not sent and writer.current().phase == "loop":
                sent.append(signum)  # in this process only where the main thread meets it
                signal.raise_signal(signum)

        yield update

    from designopt.cli import commands as cli_main

    monkeypatch.setattr(cli_main, "_progress", lambda quiet: bar)


@pytest.mark.parametrize("chain", range(6))
def test_random_stops_in_process_then_resume_equals_uninterrupted(
    tmp_path, monkeypatch, capsys, reference, chain
):
    """A chain of runs, each stopped by a random signal at a random iteration and
    continued with the printed command; the last one finishes and equals the reference."""
    rng = random.Random(1000 + chain)
    cfg = config(tmp_path, "checkpoint_every_s: 3600\n")  # only the stop writes a checkpoint
    out = tmp_path / "a.h5"
    earlier = copy(reference, out)
    args = ["run", cfg, "--quiet", "--no-figures", "--overwrite", "--out", out]
    done = 0
    while (it := done + rng.randint(1, 8)) < N_ITERS - 3:
        sig = rng.choice(list(CODES))
        _signal_at(monkeypatch, it, sig)  # a resumed run's bar starts at its checkpoint
        rc, _, err = run_cli(capsys, *args)
        assert rc == CODES[sig], err
        msg = one_line(err)
        assert signal.Signals(sig).name in msg and "--resume" in msg
        assert out.read_bytes() == earlier
        assert strays(tmp_path) == []
        with archive.h5py.File(archive.partial_path(out)) as h:
            now = int(h["checkpoint"].attrs["done"])
        # the next boundary (chunks of 3) once this run has met its first one; a stop at
        # the loop's end keeps the checkpoint of its last iteration
        assert now == min(max(-(-it // 3) * 3, done + 6), N_ITERS), (it, done, now)
        done = now
        args = resume_args(err)
        KILL_POINTS["in-process"] += 1
    monkeypatch.undo()
    rc, _, err = run_cli(capsys, *args)
    assert rc == 0, err
    same_result(out, reference)
    assert strays(tmp_path) == [] and not archive.partial_path(out).exists()


def _marks(path) -> dict[str, float]:
    try:
        return {k: float(v) for k, v in (ln.split() for ln in path.read_text().splitlines())}
    except FileNotFoundError:
        return {}


@pytest.fixture(scope="module")
def timing(tmp_path_factory, child_env, reference):
    """Phase marks of an uninterrupted child run (warms the compilation cache too)."""
    d = tmp_path_factory.mktemp("timing")
    env = child_env | {"FAULT_MARKS": str(d / "marks"), "FAULT_WRITE_SLEEP": "0.4"}
    for _ in range(2):  # the second run reads the compilation cache the first wrote
        (d / "marks").unlink(missing_ok=True)
        p = spawn(["run", config(d), "--quiet", "--no-figures", "--overwrite", "--out",
                   d / "a.h5"], env)  # fmt: skip
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
    same_result(d / "a.h5", reference)
    m = _marks(d / "marks")
    assert {"handlers", "loop", "write", "done"} <= set(m), m
    return m


MOMENTS = ["before compile", "during compile", "mid-optimisation", "during archive write"]
CASES = [(m, s) for m in MOMENTS for s in ("SIGINT", "SIGTERM", "SIGKILL")]


@pytest.mark.parametrize("moment,sig", CASES[:12])
def test_child_stopped_at_a_random_moment(tmp_path, capsys, child_env, timing, reference,
                                          moment, sig):  # fmt: skip
    rng = random.Random(f"{moment}{sig}")
    signum = getattr(signal, sig)
    cfg = config(tmp_path)
    out = tmp_path / "a.h5"
    earlier = copy(reference.with_name("ref.h5"), out)
    env = child_env | {"FAULT_MARKS": str(tmp_path / "marks"), "FAULT_WRITE_SLEEP": "0.4"}
    p = spawn(["run", cfg, "--quiet", "--no-figures", "--overwrite", "--out", out], env)
    h, loop, write = timing["handlers"], timing["loop"], timing["write"]
    after, delay = {
        "before compile": ("handlers", rng.uniform(0, 0.1 * (loop - h))),
        "during compile": ("handlers", rng.uniform(0.3 * (loop - h), 0.9 * (loop - h))),
        "mid-optimisation": ("loop", rng.uniform(0, 0.8 * (write - loop))),
        "during archive write": ("write", rng.uniform(0.05, 0.3)),
    }[moment]
    t0 = time.monotonic()
    while after not in _marks(tmp_path / "marks") and p.poll() is None:
        assert time.monotonic() - t0 < 120
        time.sleep(0.01)
    time.sleep(delay)
    p.send_signal(signum)
    _, err = p.communicate(timeout=120)
    KILL_POINTS["child"] += 1
    partial = archive.partial_path(out)
    if signum == signal.SIGKILL:
        assert p.returncode == -signal.SIGKILL
        finished = out.read_bytes() != earlier
    else:
        if p.returncode == 0:  # the stop came after the archive and its figures
            pytest.fail(f"not stopped: {err}")
        assert p.returncode == CODES[signum], err
        msg = one_line(err)
        assert sig in msg
        assert strays(tmp_path) == []
        finished = "is complete" in msg
        if partial.exists():
            assert "--resume" in msg and str(partial) in msg
        elif not finished:
            assert "nothing written" in msg
    if finished:
        same_result(out, reference)
        assert not partial.exists()
        return
    assert out.read_bytes() == earlier
    if moment == "during archive write" and signum != signal.SIGKILL:
        pytest.fail("a stop during the archive write must let the write finish")
    if partial.exists():
        rc, _, err = run_cli(capsys, "run", cfg, "--quiet", "--no-figures", "--overwrite",
                             "--out", out, "--resume")  # fmt: skip
        assert rc == 0, err
        if signum == signal.SIGKILL and err:  # the killed run's lock is taken over
            assert "no longer running" in one_line(err)
        same_result(out, reference)
    assert strays(tmp_path) == [] or signum == signal.SIGKILL
    rc, _, err = run_cli(capsys, "run", cfg, "--quiet", "--no-figures", "--overwrite", "--out", out)
    assert rc == 0, err
    assert strays(tmp_path) == []  # a killed writer's temporary files are swept


def test_enough_kill_points():
    """The issue asks for at least 50 randomised kill points (this module's, counted)."""
    n = KILL_POINTS["in-process"] + KILL_POINTS["child"]
    if KILL_POINTS["child"] == 0 or KILL_POINTS["in-process"] == 0:
        pytest.skip("run with the whole module to count the kill points")
    assert n >= 50, KILL_POINTS


def test_max_minutes_stops_cleanly_and_the_printed_command_finishes(tmp_path, child_env,
                                                                    timing, reference):  # fmt: skip
    """--max-minutes takes the signals' path: exit 143 with the checkpoint and the resume
    command (which repeats --max-minutes); repeating it finishes the run, as in
    scheduler slots, with the uninterrupted result."""
    out = tmp_path / "a.h5"
    partial = archive.partial_path(out)
    minutes = (timing["loop"] + 1.0) / 60  # about 1 s of a loop slowed to 2 s
    args = ["run", config(tmp_path), "--quiet", "--no-figures", "--out", out]
    env = child_env | {"FAULT_CHUNK_SLEEP": "0.1"}
    stops, done = 0, -1
    for _ in range(10):
        p = spawn([*args, "--max-minutes", f"{minutes:.6f}"], env)
        _, err = p.communicate(timeout=120)
        if p.returncode == 0 and stops == 0:
            # the whole run fitted the slot (the timing run met a busier machine): a
            # shorter slot, on a fresh output
            out.unlink()
            minutes *= 0.5
            continue
        if p.returncode == 0:
            break
        stops += 1
        assert p.returncode == 143, err
        msg = one_line(err)
        assert "time limit (--max-minutes" in msg
        if f"{out} is complete" in msg:
            break
        if partial.exists():
            cmd = resume_args(err)
            i = cmd.index("--max-minutes")
            assert float(cmd[i + 1]) == pytest.approx(float(f"{minutes:.6f}"), rel=1e-9)  # as given
            args = cmd[:i] + cmd[i + 2 :]
            with archive.h5py.File(partial) as h:
                now = int(h["checkpoint"].attrs["done"])
            if now == done:  # the slot ended before its first boundary (a busy machine)
                minutes *= 1.5
            done = now
    assert stops >= 1 and out.exists(), err
    same_result(out, reference)
    assert strays(tmp_path) == []
