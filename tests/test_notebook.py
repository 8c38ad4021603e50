"""The walkthrough notebook's twin cells run as written (the MJX cell is left to the env tests)."""

import json
from pathlib import Path

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "walkthrough.ipynb"


def test_walkthrough_twin_cells_run(capsys):
    cells = [c for c in json.loads(NOTEBOOK.read_text())["cells"] if c["cell_type"] == "code"]
    namespace: dict = {}
    for cell in cells[:2]:  # the twin cells; the third compiles MJX
        exec(compile("".join(cell["source"]), str(NOTEBOOK), "exec"), namespace)
    assert namespace["obs"].shape == (84 + 2 + 8,)  # the paper's 84, the oscillator's phase, the familiarity
    assert namespace["contact_steps"] > 0, "held random poses should touch the body"
    assert namespace["touched"].any()
