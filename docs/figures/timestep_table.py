"""How far is each step from dt → 0?

⟨U⟩/N against its dt → 0 limit, the reported T_tr and T_rot against the bath (and
``RigidLangevinBAOAB``'s end-of-step T_rot, dotted), and the configurational temperatures
where the runs carry them, for each code and integrator of the time-step table, from
``validation/timestep_table.json`` (``validation/timestep_table_report.py``); until the full
table is run, from the 216-water runs ``validation/timestep_table_216.json``, whose title
says so.  The small run of the time-step page has a figure of its own
(``timestep_table_small.py``).
"""

from _common import ROOT, read_json
from _timestep import draw_table

#: The tables drawn, the first found: (file, what the title adds).
SOURCES = (("timestep_table.json", ""),
           ("timestep_table_216.json", ": {runs} runs of 100 ps a point, not the full table"))


def _data():
    """The first table of :data:`SOURCES` that exists: (data, title's note, its path)."""
    for name, note in SOURCES:
        path = ROOT / "validation" / name
        if path.is_file():
            return read_json(path, "points", "fits"), note, path
    raise FileNotFoundError(f"none of {', '.join(n for n, _ in SOURCES)} in validation/")


def draw(path):
    data, note, source = _data()
    draw_table(data, note, source, path)
