"""Repository contracts: CI runs the README's test command; the README's main command works."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bash_blocks(text: str) -> list[str]:
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", text, flags=re.S)]


def test_ci_runs_the_readme_test_command():
    blocks = _bash_blocks((ROOT / "README.md").read_text())
    test_cmds = [b for b in blocks if "pytest" in b]
    assert len(test_cmds) == 1, test_cmds
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmds[0] in ci.splitlines()


def test_readme_main_command_is_a_known_subcommand():
    from assist.cli import build_parser

    blocks = _bash_blocks((ROOT / "README.md").read_text())
    main_cmd = blocks[0]
    assert main_cmd.startswith("pip install -e . && ptw-assist ")
    argv = main_cmd.split("ptw-assist ", 1)[1].split()
    build_parser().parse_args(argv)  # parses: the subcommand and its options exist


def _python_blocks(text: str) -> list[str]:
    return [b for b in re.findall(r"```python\n(.*?)```", text, flags=re.S)]


def test_readme_python_examples_run(tmp_path, monkeypatch):
    """Every ```python block of the README runs as printed (docs with runnable examples)."""
    import matplotlib

    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    blocks = _python_blocks((ROOT / "README.md").read_text())
    assert len(blocks) >= 4
    for i, code in enumerate(blocks):
        try:
            exec(compile(code, f"README.md python block {i + 1}", "exec"), {"__name__": "__readme__"})
        except Exception as e:  # pragma: no cover - the message names the block
            raise AssertionError(f"README python block {i + 1} fails: {e!r}\n{code}") from e
