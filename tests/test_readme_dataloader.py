"""README's DataLoader script (section "Using a dataset from PyTorch") works when pasted into a file:
the loop sits under the ``__main__`` guard that spawned workers need, and torch's threads are set.
(PyTorch is no dependency: the script itself was run by hand, README says with which build.)"""

from __future__ import annotations

import ast
import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def _script() -> str:
    text = README.read_text(encoding="utf-8")
    section = text[text.index("### Using a dataset from PyTorch"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]


def test_dataloader_script_guards_its_loop_and_sets_threads() -> None:
    tree = ast.parse(_script())
    guards = [n for n in tree.body if isinstance(n, ast.If) and ast.unparse(n.test) == "__name__ == '__main__'"]
    assert len(guards) == 1, "the DataLoader loop must run under if __name__ == '__main__':"
    inside = ast.unparse(guards[0])
    assert "DataLoader(" in inside and 'multiprocessing_context="spawn"' in inside.replace("'", '"')
    assert "torch.set_num_threads(1)" in inside
    outside = [ast.unparse(n) for n in tree.body if n is not guards[0]]
    assert all(s.startswith(("import ", "from ")) for s in outside), outside  # nothing else runs in a worker
