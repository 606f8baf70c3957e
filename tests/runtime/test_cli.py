"""``slipkit-run``: summary, --check against the manifest's budget, --json, UDP, and the import promise."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from tests.runtime.helpers import LinearCase, pin_bundle, run_cli_reporting_modules

from slipkit.runtime import UdpSender, heavy_modules_loaded
from slipkit.runtime.cli import main, run


@pytest.fixture(scope="module")
def generous(tmp_path_factory: pytest.TempPathFactory) -> LinearCase:
    """A bundle whose p99 budget is the whole 10 s frame period: every machine meets it."""
    return LinearCase(
        tmp_path_factory.mktemp("cli"), budget=(10_000.0, 10_000.0), name="generous"
    )


@pytest.fixture(scope="module")
def impossible(tmp_path_factory: pytest.TempPathFactory) -> LinearCase:
    """A bundle whose p99 budget is 1 ns: no machine meets it."""
    return LinearCase(
        tmp_path_factory.mktemp("cli"), budget=(10.0, 1e-6), name="impossible"
    )


def test_check_passes_with_a_generous_budget(
    generous: LinearCase, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--check exits 0 when p99 is within the manifest's budget, and --json holds the summary."""
    status = run([str(generous.path), "--check", "--json", str(tmp_path / "s.json")])
    summary = json.loads((tmp_path / "s.json").read_text())
    assert 0 == status
    assert (200, 197, True) == (
        summary["frames"],
        summary["decisions"],
        summary["within_budget"],
    )
    assert (
        int(np.sum(generous.scores >= generous.threshold)) == summary["slip_decisions"]
    )
    assert {"p50", "p99", "max", "mean"} == set(summary["latency_ms"])
    assert "check: passed" in capsys.readouterr().out


def test_check_fails_with_an_impossible_budget(
    impossible: LinearCase, capsys: pytest.CaptureFixture[str]
) -> None:
    """--check exits 1 when the judged p99 is over the manifest's budget, saying "over";
    without --check the run still succeeds."""
    assert 1 == run([str(impossible.path), "--check"])
    out = capsys.readouterr().out
    assert ": over;" in out
    assert "check: FAILED (over)" in out
    assert 0 == run([str(impossible.path)])


def test_replay_and_frames_options(generous: LinearCase, tmp_path: Path) -> None:
    """--replay reads a plain .npy and --frames keeps the first N frames."""
    np.save(tmp_path / "f.npy", generous.frames)
    run(
        [
            str(generous.path),
            "--replay",
            str(tmp_path / "f.npy"),
            "--frames",
            "20",
            "--json",
            str(tmp_path / "s.json"),
        ]
    )
    summary = json.loads((tmp_path / "s.json").read_text())
    assert (20, 17) == (summary["frames"], summary["decisions"])


def test_bad_bundle_exits_2_naming_the_file(
    generous: LinearCase, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A tampered bundle stops slipkit-run with status 2 and a one-line message naming the file."""
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(generous.path, bad)
    (bad / "model.onnx").write_bytes(b"\x08\x0a")
    with pytest.raises(SystemExit) as info:
        main([str(bad)])
    assert 2 == info.value.code
    assert re.search(r"slipkit-run: .*bad/model\.onnx: sha256", capsys.readouterr().err)


def test_choose_session_ranks_candidates(
    generous: LinearCase, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--choose-session measures every option set and lists them fastest (p99) first."""
    status = run(
        [
            str(generous.path),
            "--choose-session",
            "--rounds",
            "1",
            "--frames",
            "30",
            "--json",
            str(tmp_path / "c.json"),
        ]
    )
    rows = json.loads((tmp_path / "c.json").read_text())["session_candidates"]
    assert 0 == status
    assert 9 == len(rows)
    assert sorted(r["p99_ms"] for r in rows) == [r["p99_ms"] for r in rows]
    assert 'manifest "session": ' in capsys.readouterr().out


def test_runtime_never_imports_the_training_stack(tmp_path: Path) -> None:
    """A run of a pin-feature bundle in a fresh interpreter imports none of torch, sklearn, hydra, pandas."""
    bundle = pin_bundle(tmp_path)
    summary, imported = run_cli_reporting_modules(
        sys.executable, bundle, tmp_path / "s.json"
    )
    assert [] == summary["heavy_modules_loaded"]
    assert [] == heavy_modules_loaded(imported)
    assert "onnxruntime" in imported  # the importtime listing is real
    assert "slipkit.features.pins" in imported  # and covers the lazily imported op
    assert 79 == summary["decisions"]


def test_heavy_modules_loaded_sees_submodules() -> None:
    """The import check reports a heavy package from any of its submodules, once."""
    assert ["sklearn", "torch"] == heavy_modules_loaded(
        ["torch.nn", "numpy", "sklearn.svm", "torch"]
    )


def test_udp_stream_through_the_cli(generous: LinearCase, tmp_path: Path) -> None:
    """slipkit-run --udp on an ephemeral loopback port decides on every frame sent to it."""
    out = tmp_path / "u.json"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "slipkit.runtime.cli",
            str(generous.path),
            "--udp",
            "127.0.0.1:0",
            "--frames",
            "60",
            "--timeout",
            "20",
            "--json",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        line = proc.stderr.readline()
        match = re.search(r"listening on udp ([\d.]+):(\d+)", line)
        assert match, line
        with UdpSender(match.group(1), int(match.group(2))) as tx:
            tx.send_all(generous.frames[:60], generous.timestamps[:60])
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert 0 == proc.returncode, stderr
    summary = json.loads(out.read_text())
    assert (60, 57) == (summary["frames"], summary["decisions"])
    assert {
        "received": 60,
        "rejected": 0,
        "lost": 0,
        "resyncs": 0,
        "last_error": None,
        "ended": "frames",
    } == summary["udp"]
    assert "udp: 60 received" in stdout


def test_udp_listener_started_before_the_sender(
    generous: LinearCase, tmp_path: Path
) -> None:
    """--timeout counts from the first frame: a sender that starts later than it is heard."""
    out = tmp_path / "late.json"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "slipkit.runtime.cli",
            str(generous.path),
            "--udp",
            "127.0.0.1:0",
            "--timeout",
            "0.3",
            "--wait",
            "30",
            "--json",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        line = proc.stderr.readline()
        match = re.search(r"listening on udp ([\d.]+):(\d+)", line)
        assert match, line
        time.sleep(1.0)  # longer than --timeout: the sensor is started late
        with UdpSender(match.group(1), int(match.group(2))) as tx:
            tx.send_all(generous.frames[:40], generous.timestamps[:40])
        _, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert 0 == proc.returncode, stderr
    summary = json.loads(out.read_text())
    assert (40, "timeout") == (summary["frames"], summary["udp"]["ended"])


def test_udp_without_a_sender_ends_after_wait(
    generous: LinearCase, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """No frame within --wait: exit 1, and the summary says so (stdout and JSON)."""
    out = tmp_path / "none.json"
    args = [str(generous.path), "--udp", "127.0.0.1:0", "--wait", "0.3"]
    assert 1 == run([*args, "--json", str(out)])
    assert "udp: no frame arrived within --wait 0.3 s" in capsys.readouterr().out
    assert (0, "wait") == (
        json.loads(out.read_text())["frames"],
        json.loads(out.read_text())["udp"]["ended"],
    )


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_bad_wait_exits_2_naming_the_option(
    generous: LinearCase, capsys: pytest.CaptureFixture[str], value: str
) -> None:
    """A negative, NaN or infinite --wait stops with status 2 on one line naming --wait."""
    with pytest.raises(SystemExit) as info:
        main([str(generous.path), "--udp", "127.0.0.1:0", f"--wait={value}"])
    err = capsys.readouterr().err
    assert (2, 1) == (info.value.code, len(err.splitlines()))
    assert "slipkit-run: error: --wait: must be in [0, 86400] s" in err


def test_check_fails_without_decisions(
    generous: LinearCase, capsys: pytest.CaptureFixture[str]
) -> None:
    """--check exits 1 when too few frames arrive to fill one window (nothing was measured)."""
    assert 1 == run([str(generous.path), "--frames", "2", "--check"])
    assert "not measured (no decisions)" in capsys.readouterr().out


def test_bad_udp_address_exits_2(
    generous: LinearCase, capsys: pytest.CaptureFixture[str]
) -> None:
    """An --udp value that is not HOST:PORT stops with status 2 and says what is expected."""
    with pytest.raises(SystemExit) as info:
        main([str(generous.path), "--udp", "localhost"])
    assert 2 == info.value.code
    assert "--udp: must be HOST:PORT" in capsys.readouterr().err


def test_dos_like_bundle_reports_per_class_decisions(tmp_path: Path) -> None:
    """A 7-class DoS-like bundle: --check passes on its 10 ms frame and counts every class."""
    from tests.runtime.helpers import DOS_CLASSES, dos_like_bundle

    bundle = dos_like_bundle(tmp_path)
    out = tmp_path / "s.json"
    assert 0 == run([str(bundle), "--check", "--json", str(out)])
    summary = json.loads(out.read_text())
    by_class = summary["decisions_by_class"]
    assert list(DOS_CLASSES) == list(by_class)
    assert summary["decisions"] - by_class["t"] == summary["slip_decisions"]
    assert {"p99": 1.0, "frame_period": 10.0} == summary["budget_ms"]


def test_key_refuses_a_resigned_manifest_that_passes_check_without_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A signed bundle passes --check with --key; edited to threshold -1e9 with its
    manifest_sha256 recomputed, it still passes --check without --key, and with
    --key stops with status 2 and one line naming manifest.hmac."""
    from tests.runtime.helpers import edit_manifest

    from slipkit.runtime import write_bundle

    c = LinearCase(tmp_path, budget=(1000.0, 100.0))
    key = tmp_path / "lab.key"
    key.write_bytes(b"a key the lab keeps")
    man = json.loads((c.path / "manifest.json").read_text())
    for k in ("files", "manifest_sha256"):
        man.pop(k)
    signed = write_bundle(
        tmp_path / "signed",
        (c.path / "model.onnx").read_bytes(),
        man,
        replay=(c.frames, c.timestamps),
        key=key.read_bytes(),
    )
    assert 0 == run([str(signed), "--check", "--key", str(key)])
    edit_manifest(signed, lambda m: m.__setitem__("threshold", -1e9))
    capsys.readouterr()
    assert 0 == run([str(signed), "--check"])
    with pytest.raises(SystemExit) as info:
        main([str(signed), "--check", "--key", str(key)])
    err = capsys.readouterr().err.strip()
    assert 2 == info.value.code
    assert 1 == len(err.splitlines())
    assert err.startswith(
        f"slipkit-run: error: {signed / 'manifest.hmac'}: does not match"
    )


def test_key_inside_the_bundle_is_refused(
    generous: LinearCase, capsys: pytest.CaptureFixture[str]
) -> None:
    """--key pointing into the bundle folder: status 2, one line naming --key."""
    with pytest.raises(SystemExit) as info:
        main([str(generous.path), "--key", str(generous.path / "manifest.json")])
    assert 2 == info.value.code
    assert "slipkit-run: error: --key: " in capsys.readouterr().err
