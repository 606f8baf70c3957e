"""benchmarks/report.py: the page's structure, its header, failures and the atomic write."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _report() -> ModuleType:
    """benchmarks/report.py as a module (benchmarks/ is not a package)."""
    spec = importlib.util.spec_from_file_location(
        "bench_report", ROOT / "benchmarks" / "report.py"
    )
    assert spec is not None
    assert spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_report"] = mod  # dataclasses look their module up by name
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def report() -> ModuleType:
    return _report()


TABLE = "| case | us |\\n|---|---|\\n| tiny | 1.5 |"


@pytest.fixture
def fake_root(tmp_path: Path) -> Path:
    """A folder with two fake benchmark scripts: one prints a table, one fails."""
    (tmp_path / "ok.py").write_text(
        f"import sys\nprint('{TABLE}')\nprint(sys.argv[1:])\n"
    )
    (tmp_path / "bad.py").write_text(
        "print('partial row')\nraise SystemExit('bad.py: no data in /nowhere')\n"
    )
    return tmp_path


def _benches(report: ModuleType) -> tuple:
    return (
        report.Bench(
            "tiny", "Tiny table", "ok.py", ("--n", "3"), "Prints a fixed table."
        ),
        report.Bench("broken", "Broken one", "bad.py", (), "Always fails."),
    )


def test_page_structure_and_header(report: ModuleType, fake_root: Path) -> None:
    out = fake_root / "docs" / "benchmarks.md"
    rc = report.main(["--only", "tiny", "--out", str(out)], _benches(report), fake_root)
    assert rc == 0
    page = out.read_text()
    assert page.splitlines()[0] == report.MARKER
    assert "# Benchmarks" in page
    assert f"| command | `{report.COMMAND} --only tiny --out {out}` |" in page
    for field in (
        "CPU",
        "cores",
        "OS",
        "Python",
        "numpy",
        "onnxruntime",
        "scikit-learn",
        "load average (1 min)",
        "git commit",
        "date (UTC)",
    ):
        assert f"| {field} | " in page, field
    assert "## Tiny table" in page
    assert "## Broken one" not in page  # --only ran the one named
    assert "Prints a fixed table." in page
    assert "`.venv/bin/python ok.py --n 3`" in page
    assert "load average" in page
    # The benchmark's own output, as printed, in a fenced block; its args reached it.
    assert (
        "```text\n| case | us |\n|---|---|\n| tiny | 1.5 |\n['--n', '3']\n```" in page
    )
    assert "Failed" not in page


def test_failing_benchmark_is_written_and_exits_nonzero(
    report: ModuleType, fake_root: Path
) -> None:
    out = fake_root / "page.md"
    rc = report.main(["--out", str(out)], _benches(report), fake_root)
    assert rc == 1
    page = out.read_text()
    assert page.index("## Tiny table") < page.index("## Broken one")
    broken = page[page.index("## Broken one") :]
    assert "**Failed:** exit status 1: bad.py: no data in /nowhere" in broken
    assert "partial row" in broken
    assert "| tiny | 1.5 |" in page  # the other benchmark's section is whole


def test_unknown_only_name_is_refused(report: ModuleType, fake_root: Path) -> None:
    with pytest.raises(SystemExit) as exc:
        report.main(
            ["--only", "nope", "--out", str(fake_root / "p.md")],
            _benches(report),
            fake_root,
        )
    assert exc.value.code == 2
    assert not (fake_root / "p.md").exists()


def test_replaces_its_own_page_and_leaves_no_temp_file(
    report: ModuleType, fake_root: Path
) -> None:
    out = fake_root / "page.md"
    out.write_text(report.MARKER + "\nold page\n")
    assert (
        report.main(["--only", "tiny", "--out", str(out)], _benches(report), fake_root)
        == 0
    )
    assert "old page" not in out.read_text()
    assert sorted(p.name for p in fake_root.iterdir()) == ["bad.py", "ok.py", "page.md"]


def test_does_not_replace_a_file_it_did_not_write(
    report: ModuleType, fake_root: Path
) -> None:
    out = fake_root / "page.md"
    out.write_text("# hand-written notes\n")
    rc = report.main(["--only", "tiny", "--out", str(out)], _benches(report), fake_root)
    assert rc == 2
    assert out.read_text() == "# hand-written notes\n"
    with pytest.raises(SystemExit, match=r"not written by benchmarks/report\.py"):
        report.write_page(out, "x")
    assert out.read_text() == "# hand-written notes\n"


def test_failed_write_keeps_the_old_page(
    report: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "page.md"
    old = report.MARKER + "\nold page\n"
    out.write_text(old)

    def broken_replace(src: object, dst: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        report.write_page(out, report.MARKER + "\nnew page\n")
    assert out.read_text() == old
    assert [p.name for p in tmp_path.iterdir()] == ["page.md"]


def test_slug_matches_the_anchors_the_docs_link(report: ModuleType) -> None:
    assert report.slug("Runtime loop overhead") == "runtime-loop-overhead"
    assert report.slug("FSR press_sign op") == "fsr-press_sign-op"
    names = [b.name for b in report.BENCHMARKS]
    assert len(names) == len(set(names))
    for b in report.BENCHMARKS:
        assert (ROOT / b.script).is_file(), b.script


def test_timeout_ends_the_benchmark_and_its_children(
    report: ModuleType, tmp_path: Path
) -> None:
    pid_file = tmp_path / "child.pid"
    (tmp_path / "hang.py").write_text(
        "import subprocess, sys, time\n"
        "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])\n"
        f"open({str(pid_file)!r}, 'w').write(str(child.pid))\n"
        "print('started', flush=True)\n"
        "time.sleep(120)\n"
    )
    benches = (report.Bench("hang", "Hangs", "hang.py", (), "Never ends."),)
    out = tmp_path / "page.md"
    rc = report.main(["--out", str(out), "--timeout", "5"], benches, tmp_path)
    assert rc == 1
    page = out.read_text()
    assert "**Failed:** timed out after 5 s" in page
    if pid_file.exists():  # on a very slow machine the script may not get that far
        assert "started" in page
        child = int(pid_file.read_text())
        # Killed with its parent's session: gone, or a zombie left for init to reap.
        stat = Path(f"/proc/{child}/stat")
        assert not stat.exists() or stat.read_text().split(")")[-1].split()[0] == "Z"
