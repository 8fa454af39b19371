"""The examples in docs/ run as written."""
import pathlib
import re

import pytest

DOCS = pathlib.Path(__file__).resolve().parents[2] / "docs"


def python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


@pytest.mark.parametrize("doc", ["api.md"])
def test_doc_examples_run(doc, capsys):
    blocks = python_blocks(DOCS / doc)
    assert blocks, f"{doc} has no python example"
    for block in blocks:
        exec(compile(block, f"docs/{doc}", "exec"), {})
    out = capsys.readouterr().out
    assert "stick 0" in out
