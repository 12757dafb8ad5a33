"""How close are the six water models to their published properties?

Each property's deviation from the published value (the percentage
``validation/water_models.py`` prints, after the corrections its table names), with the
measurement's standard error, from ``validation/water_models.txt``.
"""

import re

import numpy as np
from _common import ROOT, DataError, figure, name, read_text, require, save

PROPERTIES = [("density", "density"), ("ΔH_vap", "ΔH_vap"), ("D∞", "D∞"), ("η", "η"),
              ("ε", "ε")]
LINE = re.compile(r"^\s{2}(\S+).*?\s([\d.]+) ± ([\d.]+).*published\s+[\d.]+ \(([-+]\d+\.\d) %\)")


def parse(text):
    models, model = {}, None
    for line in text.splitlines():
        head = re.match(r"^(\w+): \d+ molecules", line)
        if head:
            model = head.group(1)
            models[model] = {}
            continue
        match = LINE.match(line)
        if model and match:
            value, error = float(match.group(2)), float(match.group(3))
            models[model][match.group(1)] = (float(match.group(4)), 100 * error / value)
    return models


def draw(path):
    source = ROOT / "validation" / "water_models.txt"
    models = require(parse(read_text(source)), source, "no '<model>: N molecules' blocks")
    for model, props in models.items():
        missing = [key for key, _ in PROPERTIES if key not in props]
        if missing:
            raise DataError(f"{name(source)}: {model}: no {', '.join(missing)} line")
    fig, ax = figure(width=7.0, height=3.4)
    x = np.arange(len(PROPERTIES))
    width = 0.8 / len(models)
    for k, (model, props) in enumerate(models.items()):
        dev = [props[key][0] for key, _ in PROPERTIES]
        err = [props[key][1] for key, _ in PROPERTIES]
        ax.bar(x + (k - (len(models) - 1) / 2) * width, dev, width, yerr=err, capsize=2,
               label=model.upper().replace("2005", "/2005").replace("EW", "-Ew"))
    ax.axhline(0, color="k", lw=1)
    ax.set_xticks(x, [label for _, label in PROPERTIES])
    ax.set_ylabel("measured − published (%)")
    ax.set_title("Six rigid water models at 298 K, 1 bar, 216 molecules")
    ax.legend(ncols=3, fontsize=8)
    save(fig, path)
