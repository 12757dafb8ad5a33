r"""The box of one LAMMPS instance of :class:`~rigidmd.lammps.LAMMPSCalculator`, and its changes.

LAMMPS keeps a cell in lower-triangular form (:func:`lower_triangular`);
ASE's cells are rotated into it, and forces and stress rotated back.  A new
cell (a barostat) goes to LAMMPS as its own barostats give it: through the
``rigidmd_box`` command of the box plugin (:mod:`rigidmd.lammps.boxplugin`),
the new box and ``KSpace::setup()`` without a set-up run, or, at the first new
cell of an instance and where the plugin is not there, ``change_box`` and a
set-up run (:meth:`LammpsBox.change`).
"""

import numpy as np

from rigidmd.lammps.boxplugin import BoxPluginUnavailable, box_plugin, warn_fallback

__all__ = ["LammpsBox", "lammps_box", "lower_triangular", "reduce_tilt", "region_command"]


def lower_triangular(cell):
    """Rotation ``Q`` with ``cell @ Q`` lower triangular with a positive diagonal.

    Returns
    -------
    Q : numpy.ndarray, shape (3, 3) or None
        None when the cell is lower triangular already.
    lammps_cell : numpy.ndarray, shape (3, 3)
    """
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = cell.tolist()  # (floats: a barostat's every step)
    if xy == 0 and xz == 0 and yz == 0 and xx > 0 and yy > 0 and zz > 0:
        return None, cell
    det = np.linalg.det(cell)
    if det == 0:
        raise ValueError("LAMMPSCalculator: the cell has zero volume (its vectors are "
                         "linearly dependent); LAMMPS needs a right-handed cell")
    if det < 0:
        raise ValueError("LAMMPSCalculator: the cell is left-handed (negative determinant); "
                         "LAMMPS needs a right-handed cell")
    Q, R = np.linalg.qr(cell.T)
    signs = np.sign(np.diag(R))
    Q, R = Q * signs, (R.T * signs).T
    lammps_cell = R.T
    lammps_cell[np.abs(lammps_cell) < 1e-14 * np.abs(lammps_cell).max()] = 0.0
    return Q, lammps_cell


def reduce_tilt(cell):
    """The same lattice with LAMMPS's tilt limits: ``|xy|, |xz| <= lx/2``, ``|yz| <= ly/2``.

    Parameters
    ----------
    cell : numpy.ndarray, shape (3, 3)
        Lower triangular (LAMMPS's frame), rows a, b, c.

    Returns
    -------
    reduced : numpy.ndarray, shape (3, 3)
        ``b - kxy a`` and ``c - kyz b - kxz a`` for the nearest whole numbers.
    flips : tuple of int
        ``(kxy, kxz, kyz)``.
    """
    reduced = np.array(cell, dtype=float)
    kyz = int(np.rint(reduced[2, 1] / reduced[1, 1]))
    reduced[2] -= kyz * reduced[1]
    kxz = int(np.rint(reduced[2, 0] / reduced[0, 0]))
    reduced[2] -= kxz * reduced[0]
    kxy = int(np.rint(reduced[1, 0] / reduced[0, 0]))
    reduced[1] -= kxy * reduced[0]
    return reduced, (kxy, kxz, kyz)


def lammps_box(cell: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, tuple[int, int, int]]:
    """The box LAMMPS is given for the atoms' ``cell``: its frame and its reduced basis.

    LAMMPS takes a box in any basis of a lattice, but its results depend on the basis (PPPM's
    mesh follows the box edges; its minimum image and ghost atoms assume tilts within half a
    box length): 27 waters with b = (2 L, L, 0) were 0.088 eV off the same lattice given
    with b = (0, L, 0).  The basis is reduced (:func:`reduce_tilt`), as the engine reduces it.

    Returns
    -------
    rotation : numpy.ndarray, shape (3, 3) or None
        ``Q`` of :func:`lower_triangular`.
    cell : numpy.ndarray, shape (3, 3)
        The reduced lower-triangular cell (Å, LAMMPS's frame).
    flips : tuple of int
        The whole box lengths taken off the tilts, as :func:`reduce_tilt` returns them.
    """
    rotation, cell = lower_triangular(cell)
    if abs(cell[1, 0]) <= 0.5 * cell[0, 0] and abs(cell[2, 0]) <= 0.5 * cell[0, 0] \
            and abs(cell[2, 1]) <= 0.5 * cell[1, 1]:
        return rotation, cell, (0, 0, 0)  # (the usual case: nothing to reduce)
    reduced, flips = reduce_tilt(cell)
    return rotation, reduced, flips


def region_command(cell):
    """The ``region rmd_box`` command of a lower-triangular ``cell`` (Å), block or prism."""
    lengths = " ".join(f"0 {cell[k, k]:.17g}" for k in range(3))
    if cell[1, 0] or cell[2, 0] or cell[2, 1]:
        tilts = f"{cell[1, 0]:.17g} {cell[2, 0]:.17g} {cell[2, 1]:.17g}"
        return f"region rmd_box prism {lengths} {tilts} units box"
    return f"region rmd_box block {lengths} units box"


class LammpsBox:
    """The cell a LAMMPS instance has, and how a new one is given to it.

    Parameters
    ----------
    lmp : lammps.lammps
        The instance (its box created).
    execute : callable
        Runs a list of LAMMPS commands in the instance (closing it on an error).
    cell : numpy.ndarray, shape (3, 3)
        The atoms' cell (Å) the box was created for.
    rotation : numpy.ndarray, shape (3, 3) or None
        ``Q`` of :func:`lower_triangular` for ``cell``.
    triclinic : bool
        Whether the box was created triclinic.

    Attributes
    ----------
    cell : numpy.ndarray, shape (3, 3)
        The atoms' cell LAMMPS has (in the atoms' frame).
    rotation : numpy.ndarray, shape (3, 3) or None
        Positions ``@ rotation`` are in LAMMPS's frame (None: the same frame).
    triclinic : bool
    plugin : None, True or str
        The box plugin: not tried yet, loaded, or why it is not there.
    fix : bool
        Whether ``fix rigidmd/box`` is declared (at the first new cell).
    """

    def __init__(self, lmp, execute, cell, rotation, triclinic, flips=(0, 0, 0)):
        self.lmp = lmp
        self.execute = execute
        self.cell = cell.copy()
        self.rotation = rotation
        self.triclinic = triclinic
        self.flips = flips  # the reduction of the cell's basis (see lammps_box)
        self.plugin = None  # loaded when first needed
        self.fix = False
        self._lammps_cell = None  # LAMMPS's box as last read (None: to be read)
        self._boxlo = None  # LAMMPS's lower box corner (read at the first rigidmd_box)

    def change(self, cell, commands, kspace_parameters):
        """Give LAMMPS a new cell, in the same instance with the same k-space parameters.

        With the box plugin (see :mod:`rigidmd.lammps.boxplugin`): one
        ``rigidmd_box`` command (the new box and ``KSpace::setup()``; positions
        are written at the call, in LAMMPS's own images, and the step decides
        whether to re-neighbour: when an atom moved by half the skin less the box
        corners' motion, as under a barostat, or when the box itself moved by more
        than half the skin since the last build, which atoms left in place need).
        At the first new cell of an instance (the plugin's ``fix rigidmd/box`` is
        taken in by a set-up), without the plugin, or when an orthogonal box gets
        tilted: ``change_box`` and a set-up run at the call.

        The cell is rotated into LAMMPS's lower-triangular frame anew (a
        barostat that shears a general cell turns that frame a little at every
        step): positions are written in the new frame at the next call, and
        forces and stress rotated back, so a turned frame costs nothing more
        than a changed box.  An orthogonal box that gets tilted becomes
        triclinic once; LAMMPS then needs its ``kspace_style`` again, given with the
        same ``commands`` and the pinned ``kspace_parameters`` (see
        :attr:`rigidmd.lammps.LAMMPSCalculator.kspace_parameters`).  LAMMPS takes any
        tilt, but its results depend on the basis (PPPM's mesh follows it): the
        cell's basis is reduced (:func:`lammps_box`), and when the reduced basis
        flips (a tilt past half a box length), ``change_box`` and a set-up run
        re-map the atoms and their neighbours, as native LAMMPS re-neighbours at
        a flip.

        Parameters
        ----------
        cell : numpy.ndarray, shape (3, 3)
            The new cell (Å), in the atoms' frame.
        commands : list of str
            The calculator's interaction commands.
        kspace_parameters : str or None
            The pinned ``kspace_modify`` command.

        Returns
        -------
        bool
            Whether the next step must run a set-up (``change_box`` was used).
        """
        rotation, lammps_cell, flips = lammps_box(cell)
        tilted = bool(lammps_cell[1, 0] or lammps_cell[2, 0] or lammps_cell[2, 1])
        # A flip of the reduced basis moves LAMMPS's periodic images of the ghost atoms
        # (native LAMMPS re-neighbours there): the set-up path below.
        flipped, self.flips = flips != self.flips, flips
        if self.fix and (self.triclinic or not tilted) and not flipped:
            # LAMMPS's barostat path (see rigidmd.lammps.boxplugin): the new box and
            # KSpace::setup() now; the next step re-neighbours if the box moved enough.
            (lx, _, _), (xy, ly, _), (xz, yz, lz) = lammps_cell.tolist()
            if self._boxlo is None:
                self._boxlo = self.lmp.extract_box()[0]
            self.execute([f"rigidmd_box {lx:.17g} {ly:.17g} {lz:.17g} {xy:.17g} {xz:.17g} "
                          f"{yz:.17g}"])
            # The box LAMMPS now has, as lammps_cell would read it (the plugin sets
            # boxhi = boxlo + length from the 17 digits, which give the same double):
            # reading it back costs 20 us inside a step, a barostat's every step.
            x0, y0, z0 = self._boxlo
            box = np.array([[(x0 + lx) - x0, 0.0, 0.0], [xy, (y0 + ly) - y0, 0.0],
                            [xz, yz, (z0 + lz) - z0]])
            box.flags.writeable = False
            self._lammps_cell = box
            self.rotation = rotation
            self.cell = cell.copy()
            return False
        setup = []
        if not self.fix and self.load_plugin():
            # The first new cell: the set-up below takes in fix rigidmd/box (as it
            # would a barostat fix); later cells then need no set-up.
            setup.append("fix rmd_box all rigidmd/box")
            self.fix = True
        if not self.fix:
            warn_fallback(self.plugin)
        if tilted and not self.triclinic:
            setup.append("change_box all triclinic")
            setup += [c for c in commands if c.split()[0] in ("kspace_style", "kspace_modify")]
            if kspace_parameters is not None:
                setup.append(kspace_parameters)
            self.triclinic = True
        box = "change_box all " + " ".join(
            f"{axis} final 0 {lammps_cell[k, k]:.17g}" for k, axis in enumerate("xyz"))
        if self.triclinic:
            box += (f" xy final {lammps_cell[1, 0]:.17g} xz final {lammps_cell[2, 0]:.17g} "
                    f"yz final {lammps_cell[2, 1]:.17g}")
        self._lammps_cell = None
        self.execute(setup + [box + " units box"])
        self.rotation = rotation
        self.cell = cell.copy()
        return True

    def load_plugin(self):
        """Whether the box plugin is loaded in this instance (tried once per instance)."""
        if self.plugin is None:
            try:
                box_plugin(self.lmp)
                self.plugin = True
            except BoxPluginUnavailable as err:
                self.plugin = str(err)
        return self.plugin is True

    def lammps_cell(self):
        """The box LAMMPS has (Å, lower triangular, in LAMMPS's frame), shape (3, 3).

        Read from LAMMPS once per box (the box changes only through :meth:`change`);
        the array returned is shared: do not modify it.
        """
        if self._lammps_cell is None:
            boxlo, boxhi, xy, yz, xz, _, _ = self.lmp.extract_box()
            lengths = np.array(boxhi) - np.array(boxlo)
            cell = np.array([[lengths[0], 0, 0], [xy, lengths[1], 0], [xz, yz, lengths[2]]])
            cell.flags.writeable = False
            self._lammps_cell = cell
        return self._lammps_cell
