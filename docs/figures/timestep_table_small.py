"""What does the small run of the time-step page show?

⟨U⟩/N against its dt → 0 limit and the reported T_tr and T_rot against the bath
(``RigidLangevinBAOAB``'s end-of-step T_rot dotted) of the small run on the time-step page:
64 TIP4P/2005 waters, ``RigidLangevin`` and ``RigidLangevinBAOAB`` at 1, 2 and 4 fs, from
``validation/timestep_table_small.json`` (``validation/timestep_table_report.py --name
timestep_table_small``).  The table's own figure is ``timestep_table.py``.
"""

from _common import ROOT, read_json
from _timestep import draw_table

SOURCE = ROOT / "validation" / "timestep_table_small.json"


def draw(path):
    draw_table(read_json(SOURCE, "points", "fits"), ": the small run, not the table", SOURCE,
               path)
