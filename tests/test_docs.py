"""The README's Python example and the docstring examples run and say what they claim."""

import doctest
import re
from pathlib import Path

import pytest

import formationlab
import formationlab.formation.spec
import formationlab.formation.templates
import formationlab.registry
import formationlab.simulation.run

ROOT = Path(__file__).resolve().parents[1]


def test_readme_python_example_runs(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the example saves its figure in the current folder
    text = (ROOT / "README.md").read_text()
    block = re.search(r"## Python API\s+```python\n(.*?)```", text, re.S)
    assert block, "README has no Python API example"
    code = block.group(1)
    assert len(code.strip().splitlines()) <= 12  # "about ten lines"
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out.split()
    assert out[0] == "desired" and float(out[1]) < 1e-3
    assert (tmp_path / "trajectories.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "module",
    [
        formationlab,
        formationlab.registry,
        formationlab.simulation.run,
        formationlab.formation.spec,
        formationlab.formation.templates,
    ],
)
def test_docstring_examples(module):
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


def test_public_api_is_curated():
    for name in formationlab.__all__:
        assert hasattr(formationlab, name), name
        obj = getattr(formationlab, name)
        if callable(obj):
            assert obj.__doc__, f"{name} has no docstring"
