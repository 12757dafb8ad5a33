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


@pytest.mark.parametrize("name", ["SIGTERM", "SIGINT", "SIGUSR1", "SIGHUP"])
def test_a_signal_after_the_command_ended_is_said_and_the_status_kept(name):
    """A SIGTERM arriving after ``rigidmd relax`` had printed its result (outputs whole)
    killed it without a word, exit 143: the command's handlers were gone and the default
    action was back for the interpreter's shut-down.  Now it is said in one line and the
    status is the command's; before the command ends the default action holds."""
    import subprocess
    import sys

    after = (f"from rigidmd.run.signals import run_command; import os, signal; "
             f"status = run_command(lambda: 3); os.kill(os.getpid(), signal.{name}); "
             f"print('still here'); raise SystemExit(status)")
    result = subprocess.run([sys.executable, "-c", after], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 3 and "still here" in result.stdout, result
    assert result.stderr.strip() == (f"rigidmd: {name} arrived after the command had ended; "
                                     "its outputs are whole")
    during = (f"from rigidmd.run.signals import run_command; import os, signal; "
              f"run_command(lambda: os.kill(os.getpid(), signal.{name}) or 0); "
              f"print('still here')")
    result = subprocess.run([sys.executable, "-c", during], capture_output=True, text=True,
                            timeout=120)
    assert "still here" not in result.stdout
    if name == "SIGINT":
        assert "KeyboardInterrupt" in result.stderr
    else:
        assert result.returncode == -getattr(signal, name)
