"""README "Benchmark your own method": its code blocks, run exactly as printed in an empty folder."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from tests.harness.harness_testdata import ROOT

README = ROOT / "README.md"
SECTION = "## Benchmark your own method"


def _blocks() -> list[tuple[str, str]]:
    """(language, text) of every fenced block of the section, in order."""
    text = README.read_text()
    start = text.index(SECTION)
    end = text.index("\n## ", start + len(SECTION))
    return re.findall(r"```(\w+)\n(.*?)```", text[start:end], flags=re.S)


def test_the_section_has_a_plugin_a_suite_and_commands():
    langs = [lang for lang, _ in _blocks()]
    assert langs == ["python", "yaml", "bash"]
    plugin = _blocks()[0][1]
    assert plugin.startswith("# my_flow.py\n") and len(plugin.splitlines()) <= 22


@pytest.mark.slow
def test_the_blocks_run_as_printed(tmp_path, cli_env):
    for lang, text in _blocks():
        if lang in ("python", "yaml"):
            name = text.splitlines()[0].removeprefix("# ").strip()
            (tmp_path / name).write_text(text)
    env = dict(cli_env)
    # the project importable as an installed aerobench would be; the plugin only through the working folder
    env["PYTHONPATH"] = str(ROOT)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    commands = _blocks()[2][1]
    done = subprocess.run(["bash", "-e", "-c", commands], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    report = (tmp_path / "runs" / "mine-again" / "report.html").read_text()
    assert "Gate: PASSED" in report
    assert '<h3>thesis-lk vs thesis-hs</h3>' in report
    assert '<th scope="row">smoothed-lk</th>' in report
    assert (tmp_path / "verdict.json").is_file() and (tmp_path / "my-baseline.json").is_file()
