"""Reading MD logs (rigidmd's and ASE's) and plotting them."""

from pathlib import Path

import numpy as np

__all__ = ["read_log", "plot_log", "temperature_curves", "LogError"]


class LogError(ValueError):
    """A file that is not an MD log."""


def read_log(path):
    """Columns of an MD log by header name, e.g. ``"Time[ps]"``, ``"Econs[eV]"``, ``"T[K]"``.

    Reads the logs of :class:`~rigidmd.core.logger.RigidLogger` and of ASE's
    ``MDLogger`` (header lines are skipped; the last header names the columns).

    Returns
    -------
    dict of str to numpy.ndarray
    """
    names, rows = None, []
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if "\0" in line:
                    raise UnicodeError
                parts = line.split()
                if not parts:
                    continue
                try:
                    rows.append([float(v) for v in parts])
                except ValueError:
                    names = parts
    except UnicodeError:
        raise LogError(f"log: {path} is not an MD log but a binary file (a trajectory or "
                       "checkpoint?); give the run's text log, e.g. md.log") from None
    if not rows or names is None:
        raise LogError(f"log: {path} holds no MD log lines")
    missing = [name for name in ("Time[ps]", "Etot[eV]", "Epot[eV]", "Ekin[eV]", "T[K]")
               if name not in names]
    if missing and "Etot/N[eV]" in names:
        raise LogError(f"log: {path} holds energies per atom (Etot/N[eV]: ASE's MDLogger with "
                       "peratom=True), which the plot does not read; log the totals "
                       "(peratom=False)")
    if missing:
        raise LogError(f"log: {path} is not an MD log (no {missing[0]} column)")
    # A line cut short (the last one of a killed run) is left out, not every column with it.
    whole = [row for row in rows if len(row) == len(names)]
    if whole:
        rows, width = whole, len(names)
    else:
        width = min(len(row) for row in rows)
    data = np.array([row[:width] for row in rows])
    return {name: data[:, i] for i, name in enumerate(names[:width])}


def temperature_curves(columns):
    """``[(label, values)]`` of the temperature panel: T, and T_tr and T_rot when logged.

    Logs written before those columns existed (and ASE's) have T only.
    """
    curves = [("T", columns["T[K]"])]
    for name, label in (("T_tr[K]", "T_tr (translation)"), ("T_rot[K]", "T_rot (rotation)")):
        if name in columns:
            curves.append((label, columns[name]))
    return curves


def plot_log(log, png, title=None):
    """Energies, temperature and (when logged) pressure and density against time, to ``png``.

    The first panel shows the conserved energy (the total energy in NVE; with
    a thermostat or barostat the quantity they conserve, as logged in
    ``Econs``), in meV from its first value; 6 logged decimals make its drift
    a line, not steps.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = read_log(log)
    t = columns["Time[ps]"]
    conserved = columns.get("Econs[eV]", columns["Etot[eV]"])
    nve = "Econs[eV]" not in columns or np.allclose(conserved, columns["Etot[eV]"], atol=1e-9)
    label = "total energy (NVE)" if nve else "conserved energy"
    npt = "rho[g/cm3]" in columns
    fig, axes = plt.subplots(4 if npt else 3, 1, sharex=True, figsize=(7, 10 if npt else 8))
    axes[0].plot(t, 1000 * (conserved - conserved[0]), color="C0", label=label)
    if not nve:
        axes[0].plot(t, 1000 * (columns["Etot[eV]"] - conserved[0]), color="C0", alpha=0.3,
                     lw=0.8, label="total energy")
    axes[0].set_ylabel("energy − initial (meV)")
    axes[0].legend(loc="best")
    axes[0].set_title(title or f"rigidmd run: {Path(log).resolve().parent.name}/{Path(log).name}")
    axes[1].plot(t, columns["Epot[eV]"] - columns["Epot[eV]"][0], label="potential", color="C1")
    axes[1].plot(t, columns["Ekin[eV]"] - columns["Ekin[eV]"][0], label="kinetic", color="C2")
    axes[1].set_ylabel("energy − initial (eV)")
    axes[1].legend(loc="best")
    curves = temperature_curves(columns)
    for (label, values), color, width in zip(curves, ("C3", "C5", "C6"), (1.5, 0.8, 0.8),
                                             strict=False):
        axes[2].plot(t, values, color=color, lw=width, label=label)
    axes[2].set_ylabel("temperature (K)")
    if len(curves) > 1:
        axes[2].legend(loc="best")
    if npt:
        axes[3].plot(t, columns["rho[g/cm3]"], color="C4")
        axes[3].set_ylabel("density (g/cm³)")
    axes[-1].set_xlabel("time (ps)")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png
