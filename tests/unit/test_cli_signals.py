"""The command line's signal handling: one line and the signal's exit code, however the
signal lands."""

from __future__ import annotations

import logging
import os
import signal
import sys
import warnings

import pytest

from braidsim.cli.common import Interrupted, signals_handled


@pytest.fixture
def restore_logging_and_hooks():
    """The handler silences logging for a stopping process: undo it for the next tests."""
    hook = sys.unraisablehook
    with warnings.catch_warnings():
        yield
    sys.unraisablehook = hook
    logging.disable(logging.NOTSET)


def test_a_signal_raised_in_the_main_flow_is_the_interruption(restore_logging_and_hooks):
    with pytest.raises(Interrupted) as info, signals_handled():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs between bytecodes
            pass
    assert info.value.signum == signal.SIGTERM


def test_a_failure_after_a_swallowed_signal_is_reported_as_the_signal(
    restore_logging_and_hooks,
):
    """Python drops an exception raised inside ``__del__`` (or a weakref callback): a signal
    landing there must still decide how the command ends, not the failure that follows."""
    dropped: list[BaseException] = []
    sys.unraisablehook = lambda u: dropped.append(u.exc_value)

    class Collected:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):
                pass

    with pytest.raises(Interrupted) as info, signals_handled():
        Collected()  # freed at once: the handler's exception is raised in __del__
        assert dropped and isinstance(dropped[0], Interrupted)
        raise RuntimeError("the workers are gone")  # what the killed workers lead to
    assert info.value.signum == signal.SIGTERM
    assert info.value.__cause__ is None


def test_a_failure_with_no_signal_stays_what_it_is():
    with pytest.raises(RuntimeError, match="plain"), signals_handled():
        raise RuntimeError("plain")


def test_the_stopping_process_says_nothing_but_its_line(restore_logging_and_hooks, capsys):
    """A local Dask cluster logs its closed connections as it closes; after the signal
    nothing is logged and an un-awaited coroutine does not warn."""
    log = logging.getLogger("distributed.batched")
    with pytest.raises(Interrupted), signals_handled():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):
            pass
    log.error("Batched Comm Closed")

    async def cut_off() -> None:
        pass

    with warnings.catch_warnings(record=True) as seen:
        coro = cut_off()
        del coro
    assert not [w for w in seen if "never awaited" in str(w.message)]
    assert "Batched" not in capsys.readouterr().err
