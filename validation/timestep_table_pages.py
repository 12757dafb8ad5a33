"""Put the collector's tables of the 216-water time-step table on the docs' pages.

The collector (``timestep_table_report.py``) writes ``validation/<name>.md``; this puts each
of its tables on the pages that show it, replacing the table with the same header row, so
the pages are the collected runs and nothing kept by hand.  The points and goals tables
are shown in two parts each (a page holds at most 2000 words): rigidmd's rows on
``timestep-216-tables.md`` and ``timestep-216-goals.md``, LAMMPS's and OpenMM's on
``timestep-216-codes.md``.  The plan page (the runs that would
decide each unresolved goal) is written whole, for TIP4P/2005 and SPC/E.  A test
(``tests/physics/test_timestep_table.py``) checks that every row is on a page.  Run::

    python validation/timestep_table_report.py validation/timestep_table_216.runs.json \\
        NEW_RUNS.json --name timestep_table_216 --borrow-limit lammps=rigidmd --bundle
    python validation/timestep_table_pages.py
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "validation"
POINTS = "| model | N | code | integrator | dt (fs) | runs | ps |"
GOALS = "| code | integrator | dt (fs) | U (±"
PLAN = "| code | integrator | dt (fs) | runs | U |"
_OTHER_CODES = {POINTS: ("| tip4p2005 | 216 | lammps |", "| tip4p2005 | 216 | openmm |"),
                GOALS: ("| lammps |", "| openmm |")}
#: Page -> {table header -> the rows of that table it shows}; a table not named: all rows.
#: The points and goals tables are each shown in two parts, rigidmd's and the other codes'.
PAGES = {
    "timestep_table_216": {"timestep-216.md": {},
                           "timestep-216-goals.md": {GOALS: ("| rigidmd |",)},
                           "timestep-216-tables.md": {POINTS: ("| tip4p2005 | 216 | rigidmd |",)},
                           "timestep-216-codes.md": _OTHER_CODES,
                           "timestep-216-runs.md": {}},
    "timestep_table_216_spce": {"timestep-216-spce.md": {}},
}


def tables(lines):
    """``[(first line, lines)]`` of the Markdown tables in ``lines``."""
    out, current, start = [], [], None
    for i, line in enumerate([*lines, ""]):
        if line.startswith("|"):
            if not current:
                start = i
            current.append(line)
        elif current:
            out.append((start, current))
            current = []
    return out


def put(name, pages):
    new = {t[0]: t for _, t in tables((ROOT / "validation" / f"{name}.md").read_text()
                                      .splitlines())}
    for page, rows in pages.items():
        path = DOCS / page
        lines = path.read_text().splitlines()
        for start, old in reversed(tables(lines)):
            table = new.get(old[0])
            if table is None or table[0].startswith(PLAN):
                continue
            shown = next((kept for header, kept in rows.items()
                          if table[0].startswith(header)), None)
            if shown is not None:
                table = table[:2] + [r for r in table[2:] if r.startswith(shown)]
            lines[start:start + len(old)] = table
        path.write_text("\n".join(lines) + "\n")


def plan_page():
    """The plan page: its text, and the plan tables of both models."""
    path = DOCS / "timestep-216-plan.md"
    text = path.read_text()
    head, tail = text[:text.index("## TIP4P/2005")], text[text.index("A run of 100 ps"):]

    def plan(name):
        t = (ROOT / "validation" / f"{name}.md").read_text()
        i = t.index(PLAN)
        return t[i:t.index("\n\n", i)]

    path.write_text(f"{head}## TIP4P/2005\n\n{plan('timestep_table_216')}\n\n## SPC/E\n\n"
                    f"{plan('timestep_table_216_spce')}\n\n{tail}")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0]).parse_args()
    for name, pages in PAGES.items():
        put(name, pages)
    plan_page()
