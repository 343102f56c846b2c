"""Every Python snippet of the READMEs runs (from the repository root, where the fixtures are)."""

import os
import re

import pytest


def _snippets(path):
    text = path.read_text()
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


@pytest.mark.parametrize("readme", ["README.md", "hbn-py/README.md"])
def test_readme_python_snippets_run(repo, readme, monkeypatch, capsys):
    snippets = _snippets(repo / readme)
    assert snippets, f"{readme} has no Python snippet"
    monkeypatch.chdir(repo)
    for code in snippets:
        exec(compile(code, readme, "exec"), {"__name__": "__readme__"})
