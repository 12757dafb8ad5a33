"""Stop signals turned into a stop between steps (rigidmd.run.signals)."""

import os
import signal

import pytest

from rigidmd.run.signals import EXIT_STATUS, StopRequest, StopSignals


def test_exit_statuses_are_128_plus_the_signal():
    assert EXIT_STATUS == {signum: 128 + int(signum) for signum in EXIT_STATUS}
    assert set(EXIT_STATUS) == {signal.SIGINT, signal.SIGTERM, signal.SIGUSR1}


def test_a_signal_becomes_a_stop_request_at_the_next_check():
    before = signal.getsignal(signal.SIGTERM)
    with StopSignals() as stops:
        stops.check()  # nothing yet
        os.kill(os.getpid(), signal.SIGTERM)
        assert stops.signum == signal.SIGTERM
        with pytest.raises(StopRequest, match="SIGTERM") as err:
            stops.check()
        assert err.value.signum == signal.SIGTERM and stops.shielded
        os.kill(os.getpid(), signal.SIGINT)  # shielded: counted, not raised
        assert stops.ignored == 1 and stops.signum == signal.SIGTERM
    assert signal.getsignal(signal.SIGTERM) is before  # the handlers are put back


def test_a_second_ctrl_c_interrupts_at_once():
    with StopSignals() as stops:
        os.kill(os.getpid(), signal.SIGINT)
        assert stops.signum == signal.SIGINT
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
