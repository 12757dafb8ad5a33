"""What a run tells its user: progress on stderr, what it is, and a summary at the end.

* :class:`Progress`: a progress bar on a terminal, a line every 1 % or 30 s otherwise.
* :func:`observables`: the row recorded every ``outputs.interval`` steps for the summary.
* :func:`describe` and :func:`summary`: the run in words, before and after the steps.
"""

import sys
import time

import numpy as np
from ase import units

from rigidmd.config import TIME_UNITS
from rigidmd.core.dof import temperature

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
    """A progress line on stderr: in place on a terminal, else every 1 % or 30 s."""

    modifies_atoms = False

    def __init__(self, dyn, total, stream=None, width=30):
        self.dyn, self.total, self.width = dyn, max(int(total), 1), width
        self.stream = sys.stderr if stream is None else stream
        self.start_step = dyn.nsteps
        self.t0 = self.last = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.next_report = 0.01

    def __call__(self):
        done = self.dyn.nsteps - self.start_step
        fraction = done / self.total
        now = time.perf_counter()
        rate = done / (now - self.t0) if now > self.t0 else 0.0
        bar = "#" * int(self.width * fraction)
        line = (f"[{bar:<{self.width}}] {done:>{len(str(self.total))}}/{self.total} steps "
                f"{rate:8.1f} steps/s  T {temperature(self.dyn.atoms):7.1f} K"
                f"{time_left(self.total - done, rate)}")
        if self.tty:
            self.stream.write("\r" + line + ("\n" if done >= self.total else ""))
        elif fraction + 1e-12 >= self.next_report or done >= self.total or now - self.last > 30:
            self.stream.write(line + "\n")
            self.next_report = np.floor(fraction * 100 + 1) / 100
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


def summary(dyn, rows, elapsed, stream):
    """Steps, speed, temperature, energy drift and (NPT) mean pressure, volume, density."""
    label = "conserved energy" if dyn.couplings else "total energy"
    print(f"{dyn.nsteps} steps ({elapsed:.1f} s for this run); "
          f"T = {dyn.get_reported_kinetic_energy()[1]:.1f} K ({dyn.degrees_of_freedom} degrees of "
          "freedom)", file=stream)
    T_tr, T_rot = dyn.get_kinetic_temperatures()
    where = " (after the O step)" if dyn.reports_own_kinetic_energies else ""
    print(f"T_tr = {T_tr:.1f} K, T_rot = {T_rot:.1f} K{where}", file=stream)
    for part in dyn.couplings:  # a part that reports on itself (the Monte Carlo barostat)
        report = getattr(part, "report", None)
        if callable(report):
            print(report(), file=stream)
    if len(rows) >= 3:
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

