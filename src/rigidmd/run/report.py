"""What a run tells its user: progress on stderr, what it is, and a summary at the end.

* :class:`Progress`: a progress bar on a terminal, otherwise a line each tenth of the run
  (at most one a minute).
* :func:`observables`: the row recorded every ``outputs.interval`` steps for the summary.
* :func:`describe` and :func:`summary`: the run in words, before and after the steps.
"""

import sys
import time

import numpy as np
from ase import units

from rigidmd.config import TIME_UNITS

__all__ = ["Progress", "time_left", "observables", "describe", "summary"]


def time_left(steps, rate):
    """``"  12m05s left"`` for ``steps`` more at ``rate`` steps per second; empty when unknown."""
    if steps <= 0 or not rate > 0:
        return ""
    seconds = int(round(steps / rate))
    hours, rest = divmod(seconds, 3600)
    text = f"{hours}h{rest // 60:02d}m" if hours else f"{rest // 60}m{rest % 60:02d}s"
    return f"  {text} left"


class Progress:
    """A progress line on stderr: in place on a terminal, else a line each tenth of the run.

    The speed and the time left are measured from the steps after the first
    report (the first steps include numba's compilation, seconds for steps of
    milliseconds) and shown once :attr:`TIMED_STEPS` of them have been timed;
    until then the speed reads ``--``.  Off a terminal (a batch job's log) a
    line is written when a tenth of the run's steps has passed since the last,
    but never two within :attr:`MIN_INTERVAL_S` (a line due sooner waits for
    it), and always at the last step: a short run writes one line, a long one
    ten.  The MD log holds every ``outputs.interval``.
    """

    modifies_atoms = False

    #: Steps after the first report that must have been timed before a speed is shown.
    TIMED_STEPS = 10
    #: Off a terminal: the least time between two lines (s), and the share of steps between.
    MIN_INTERVAL_S = 60.0
    SHARE = 0.1

    def __init__(self, dyn, total, stream=None, width=30):
        self.dyn, self.total, self.width = dyn, max(int(total), 1), width
        self.stream = sys.stderr if stream is None else stream
        self.start_step = dyn.nsteps
        self.last = time.perf_counter()
        self.timed_from = None  # (steps done, time) at the first report after a step
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.next_report = self.SHARE

    def _rate(self, done, now):
        """Steps per second since the first report after a step; None until enough are timed."""
        if self.timed_from is None:
            if done > 0:
                self.timed_from = (done, now)
            return None
        steps, since = done - self.timed_from[0], now - self.timed_from[1]
        return steps / since if steps >= self.TIMED_STEPS and since > 0 else None

    def __call__(self):
        done = self.dyn.nsteps - self.start_step
        fraction = done / self.total
        now = time.perf_counter()
        rate = self._rate(done, now)
        bar = "#" * int(self.width * fraction)
        speed = f"{rate:8.1f}" if rate is not None else f"{'--':>8}"
        line = (f"[{bar:<{self.width}}] {done:>{len(str(self.total))}}/{self.total} steps "
                f"{speed} steps/s  T {self.dyn.get_reported_kinetic_energy()[1]:7.1f} K"
                f"{time_left(self.total - done, rate or 0.0)}")
        if self.tty:
            self.stream.write("\r" + line + ("\n" if done >= self.total else ""))
        elif done >= self.total or (fraction + 1e-12 >= self.next_report
                                    and now - self.last >= self.MIN_INTERVAL_S):
            self.stream.write(line + "\n")
            self.next_report = (np.floor(fraction / self.SHARE + 1e-9) + 1) * self.SHARE
            self.last = now
        self.stream.flush()


def observables(dyn):
    """Time, conserved energy and, under a barostat, pressure (bar), volume, density."""
    row = (dyn.get_time(), dyn.get_conserved_energy())
    if dyn.evaluator.cell_moves:
        # A Monte Carlo barostat runs with calculators that have no stress: no pressure then.
        stress = "stress" in getattr(dyn.atoms.calc, "implemented_properties", ("stress",))
        pressure = dyn.get_pressure() / units.bar if stress else np.nan
        row += (pressure, dyn.get_volume(), dyn.get_density())
    return row


def describe(dyn):
    """What the run is, in words: NVE, or its coupling parts."""
    parts = []
    for part in dyn.couplings:
        text = f"{part.kind} {part.section}"
        if hasattr(part, "pressure_au"):
            text += f" at {part.pressure_au / units.bar:g} bar ({part.couple})"
        elif hasattr(part, "temperature_K"):
            text += f" at {part.temperature_K:g} K"
        parts.append(text)
    return ", ".join(parts) or "NVE"


def summary(dyn, rows, elapsed, stream, steps=None, resumed_at=0):
    """Steps, speed, temperature, energy drift and (NPT) mean pressure, volume, density.

    Parameters
    ----------
    dyn : rigidmd.RigidDynamics
    rows : list of tuple
        :func:`observables` of the steps run now.
    elapsed : float
        Seconds the steps took.
    stream : file
    steps : list of int, optional
        The step of each row; the summary names the steps its statistics cover.
    resumed_at : int, default 0
        The step a ``--resume`` continued from: the statistics then cover only
        the part run since, and say so.
    """
    label = "conserved energy" if dyn.couplings else "total energy"
    done = (f"{dyn.nsteps - resumed_at} since --resume at step {resumed_at}, {elapsed:.1f} s"
            if resumed_at else f"{elapsed:.1f} s for this run")
    print(f"{dyn.nsteps} steps ({done}); T = {dyn.get_reported_kinetic_energy()[1]:.1f} K "
          f"({dyn.degrees_of_freedom} degrees of freedom)", file=stream)
    T_tr, T_rot = dyn.get_kinetic_temperatures()
    where = " (after the O step)" if dyn.reports_own_kinetic_energies else ""
    print(f"T_tr = {T_tr:.1f} K, T_rot = {T_rot:.1f} K{where}", file=stream)
    for part in dyn.couplings:  # a part that reports on itself (the Monte Carlo barostat)
        report = getattr(part, "report", None)
        if callable(report):
            print(report(), file=stream)
    if len(rows) >= 3:
        if steps:
            span = f"statistics over steps {steps[0]}-{steps[-1]}"
            print(f"{span} only: the part run since --resume at step {resumed_at}" if resumed_at
                  else f"{span} (the run from its start)", file=stream)
        data = np.array(rows)
        t_ps, e = data[:, 0] / TIME_UNITS["ps"], data[:, 1]
        drift = np.polyfit(t_ps, e, 1)[0]
        print(f"{label}: drift {drift:+.2e} eV/ps, max |E - E0| {np.abs(e - e[0]).max():.2e} eV",
              file=stream)
        if data.shape[1] > 2:
            pressure, volume, density = data[:, 2:].T
            mean_p = "" if np.isnan(pressure).all() else f"mean P = {pressure.mean():.1f} bar, "
            print(f"{mean_p}V = {volume.mean():.1f} Å³, "
                  f"density = {density.mean():.4f} g/cm³ (final {density[-1]:.4f})",
                  file=stream)
