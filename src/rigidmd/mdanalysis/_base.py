"""What every part of :mod:`rigidmd.mdanalysis` shares.

The optional import of MDAnalysis (and the error saying how to install it),
units, selections, whole-residue arithmetic, time-correlation helpers and
the figure helpers of the ``plot`` methods.
"""

import numpy as np
from ase import units

try:  # MDAnalysis is optional: everything checks for it when used.
    import MDAnalysis as mda
    from MDAnalysis.analysis.base import AnalysisBase
    from MDAnalysis.analysis.rdf import InterRDF
    from MDAnalysis.lib.distances import minimize_vectors
except ImportError as _error:  # pragma: no cover - exercised in a subprocess test
    mda = None
    _IMPORT_ERROR = _error

    class AnalysisBase:
        """Placeholder used when MDAnalysis is missing; using it raises ImportError."""

        def __init__(self, *args, **kwargs):
            require_mdanalysis()

    InterRDF = AnalysisBase
    minimize_vectors = None
else:
    _IMPORT_ERROR = None

#: One picosecond in ASE time units.
PS = 1000.0 * units.fs

#: Å²/ps expressed in cm²/s.
ANGSTROM2_PER_PS_IN_CM2_PER_S = 1e-4

INSTALL_HINT = (
    'rigidmd.mdanalysis needs MDAnalysis; install it with pip install "rigidmd[analysis]"'
)


def require_mdanalysis():
    """Raise a helpful ImportError if MDAnalysis is not installed."""
    if mda is None:
        raise ImportError(INSTALL_HINT) from _IMPORT_ERROR


def group_of(universe_or_group, select):
    """AtomGroup from a Universe or AtomGroup and a selection string (None: all of it)."""
    require_mdanalysis()
    atoms = universe_or_group.atoms
    group = atoms if select is None else atoms.select_atoms(select)
    if len(group) == 0:
        raise ValueError(f"the selection {select!r} matches no atoms")
    return group


class ResidueLayout:
    """Compact residue index of the atoms of a group, for whole-molecule arithmetic."""

    def __init__(self, group):
        _, self.index = np.unique(group.resindices, return_inverse=True)
        self.index = self.index.ravel()
        self.n = int(self.index.max()) + 1
        first = np.full(self.n, len(group), dtype=np.int64)
        np.minimum.at(first, self.index, np.arange(len(group)))
        self.first = first
        self.masses = group.masses.astype(float)
        self.mass = np.bincount(self.index, weights=self.masses, minlength=self.n)

    def whole(self, positions, box):
        """Positions (Å, shape (n_atoms, 3)) with every residue whole: each atom at its
        minimum image from the residue's first atom.  ``box`` is ``ts.dimensions``
        (None: no periodicity)."""
        x = np.asarray(positions, dtype=np.float64)
        if box is None:
            return x
        anchor = x[self.first][self.index]
        return anchor + minimize_vectors(x - anchor, np.asarray(box, dtype=np.float64))

    def centres_of_mass(self, positions):
        """Mass-weighted centre of every residue (Å), shape (n_residues, 3)."""
        x = np.asarray(positions, dtype=float)
        return np.stack([np.bincount(self.index, weights=self.masses * x[:, k],
                                     minlength=self.n) for k in range(3)], axis=1) \
            / self.mass[:, None]


def frame_spacing(times):
    """Time between analysed frames (ps); ValueError if they are not evenly spaced.

    Trajectory formats store times in single precision, so steps may differ
    by a few float32 spacings of the largest time.
    """
    times = np.asarray(times, dtype=float)
    if len(times) < 2:
        return 1.0
    spacing = (times[-1] - times[0]) / (len(times) - 1)
    roundoff = 8 * np.finfo(np.float32).eps * max(1.0, float(np.abs(times).max()))
    if spacing <= 0:
        raise ValueError("frames must run forward in time (a positive step) for a time "
                         "correlation")
    if np.abs(np.diff(times) - spacing).max() > 1e-3 * spacing + roundoff:
        raise ValueError("frames must be evenly spaced in time for a time correlation")
    return float(spacing)


def check_frames(owner, n_frames, least):
    """Refuse in one line a run over fewer than ``least`` frames (``start``, ``stop``,
    ``step`` or ``frames`` that select too few), naming ``owner``."""
    if n_frames < least:
        raise ValueError(f"{owner}: the frames selected (start, stop, step, frames) are "
                         f"{n_frames}; it needs at least {least}")


def autocorrelation(x, max_lag):
    """Multiple-origin autocorrelation of series along axis 0, summed over nothing else.

    ``x`` has shape (n_frames, ...); returns shape (max_lag + 1, ...) with
    ``c[m] = mean over t of x[t] * x[t + m]`` (all available origins).
    """
    n = x.shape[0]
    size = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(x, n=size, axis=0)
    acf = np.fft.irfft(f * np.conj(f), n=size, axis=0)[:max_lag + 1]
    counts = (n - np.arange(max_lag + 1)).reshape((-1,) + (1,) * (x.ndim - 1))
    return acf / counts


def unwrap_series(x, boxes):
    """Remove periodic jumps from trajectories of points (nojump), vectorised over points.

    ``x`` (n_frames, n, 3) Å, ``boxes`` (n_frames, 6) or None.  Each step is
    replaced by its minimum image in the box of the later frame.
    """
    if boxes is None or len(x) < 2:
        return x
    steps = np.diff(x, axis=0)
    boxes = np.asarray(boxes, dtype=float)
    if np.allclose(boxes[:, 3:], 90.0):
        lengths = boxes[1:, None, :3]
        steps = steps - lengths * np.round(steps / lengths)
    else:
        steps = np.stack([minimize_vectors(s.astype(np.float32), b.astype(np.float32))
                          for s, b in zip(steps, boxes[1:], strict=True)]).astype(float)
    return np.concatenate([x[:1], x[:1] + np.cumsum(steps, axis=0)])


def new_figure(figsize=(5.0, 3.6)):
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.add_subplot()


def finish_figure(fig, path):
    if path is not None:
        fig.savefig(path, dpi=150)
    return fig
