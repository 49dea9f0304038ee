"""The README's Python quick start runs as written (a user's check: its last line raised,
for a surface integrated without discontinuities)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from facetlift import io, synthetic

README = Path(__file__).resolve().parents[1] / "README.md"


def test_python_quick_start_runs_verbatim(tmp_path, monkeypatch):
    text = README.read_text()
    section = text[text.index("## Python quick start"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    gt = synthetic.analytic("occluder", 48)
    io.write_normals(tmp_path / "normal_map.png", np.nan_to_num(gt.normals))
    io.write_mask(tmp_path / "mask.png", gt.mask)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(code, str(README), "exec"), scope)  # noqa: S102 - the README's own code
    for name in ("depth.exr", "mesh.ply", "preview.png", "mesh_split.ply", "jumps.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert np.isfinite(scope["surface"].depth[gt.mask]).all()
    assert scope["jumps"].discontinuities is not None
