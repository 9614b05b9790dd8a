"""The helper process's own rules (its use by self-collision: test_springs_self_collision.py)."""
from __future__ import annotations

from physanim.core import helper_process


def test_the_helper_runs_its_blas_on_one_thread_unless_told_otherwise(monkeypatch):
    """A BLAS thread pool in the child would take the bake's core too."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(name, raising=False)
    env = helper_process._environment()
    assert env["OPENBLAS_NUM_THREADS"] == env["OMP_NUM_THREADS"] == env["MKL_NUM_THREADS"] == "1"
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    assert helper_process._environment()["OPENBLAS_NUM_THREADS"] == "3"


def test_a_helper_that_cannot_start_its_task_says_so():
    """A task the child cannot import: it ends before answering ``ready``, and the bake's side
    learns it as a HelperError (never a hang), the process ended."""
    import pytest

    helper = helper_process.Helper("no_such_module:serve", {})
    with pytest.raises(helper_process.HelperError, match="did not start"):
        helper.wait_ready(timeout=60)
    assert not helper.alive and helper._proc.poll() is not None


def test_a_write_to_an_ended_child_is_made_an_error_not_the_end_of_the_process():
    """SIGPIPE left at its default by an embedding program: on the main thread it is ignored
    from then on (as Python sets it at start-up) and children may start; on another thread it
    cannot be set, and none start."""
    import signal
    import threading

    before = signal.getsignal(signal.SIGPIPE)
    try:
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
        seen = []
        thread = threading.Thread(target=lambda: seen.append(helper_process.pipes_safe()))
        thread.start()
        thread.join()
        assert seen == [False] and signal.getsignal(signal.SIGPIPE) == signal.SIG_DFL
        assert helper_process.pipes_safe()
        assert signal.getsignal(signal.SIGPIPE) == signal.SIG_IGN
        assert helper_process.pipes_safe()  # (already ignored)
    finally:
        signal.signal(signal.SIGPIPE, before)
