r"""Forces from an engine in another process: an ASE calculator speaking the i-PI protocol.

i-PI's socket protocol (Ceriotti, More and Manolopoulos, Comput. Phys. Commun.
185, 1019 (2014)) is spoken by LAMMPS (``fix ipi``), CP2K, Quantum ESPRESSO,
FHI-aims, DFTB+ and ASE's own :class:`ase.calculators.socketio.SocketClient`
(which wraps any ASE calculator).  :class:`IPICalculator` is the server side:
it listens on a Unix socket ``/tmp/ipi_<name>`` or a TCP port, an engine
connects, and every force call is one exchange of fixed-size messages (12-byte
headers, then native-endian ``float64``/``int32`` arrays)::

    server                     engine
    STATUS            ->
                      <-       READY (or NEEDINIT: the server sends INIT first)
    POSDATA h h^-1 N x ->      (the cell h = cell.T, Bohr; positions, Bohr)
    GETFORCE          ->
                      <-       FORCEREADY E N f W len extra
                               (Hartree, Hartree/Bohr, virial W in Hartree)

After the first exchange the ``STATUS`` polls are skipped: positions and the
request for forces go out in one write, the answer comes back in one read.

Units on the wire are atomic units.  Engines convert with their own Bohr and
Hartree: ASE's client with ASE's (the default here), LAMMPS's ``fix ipi``
with 8-digit ones (``bohr``, ``hartree`` take the engine's values, so that its
numbers come back to roundoff).

Asking for less (rigidmd's extension, for engines that know it)
    A server made with ``tally_requests=True`` sends, in the same write as
    each ``POSDATA``, a ``RMDTALLY`` header and one ``int32``: bit 0 asks for
    the energy, bit 1 for the virial, of that one configuration (forces are
    always computed).  An engine may then skip what is not asked, as native
    LAMMPS tallies energy and virial only on output steps; the calculator
    keeps only the properties asked for.  rigidmd's LAMMPS ``fix rigidmd/ipi``
    understands it; an engine that does not (``fix ipi``, ASE's client, i-PI
    drivers) would stop at the unknown header, so the flag is off by default.
    An engine's ``extra`` string (after the virial) is kept in
    :attr:`IPICalculator.engine_extra`; a length below 0 or past 16 MiB (1 kB an
    atom for more than 16384 atoms) is refused as a broken answer.

The virial ``W = -V σ`` (eV) gives the stress.  LAMMPS's ``fix ipi`` fills
only the upper triangle (xy, xz, yz) and leaves the lower one zero (ASE's own
server would symmetrise that with the zeros and halve every shear stress):
here a zero lower (or upper) triangle is mirrored from the other, and a full
virial is symmetrised.  A virial of nine exact zeros is one the engine did not
compute (ASE's ``SocketClient`` sends it unless ``run(..., use_stress=True)``): no
stress is made from it, and asking for the stress raises :class:`EngineError`.
"""

from rigidmd.ipi.calculator import IPICalculator, symmetric_virial
from rigidmd.ipi.connection import EngineError, add_wait_check, remove_wait_check

__all__ = ["EngineError", "IPICalculator", "add_wait_check", "remove_wait_check",
           "symmetric_virial"]
