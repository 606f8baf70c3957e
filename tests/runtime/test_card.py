"""The model card in a bundle: listed and checked like the graph, printed by ``slipkit-run --card``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tests.runtime.helpers import linear_graph, manifest

from slipkit.runtime import BundleError, load_bundle, write_bundle
from slipkit.runtime.bundle import CARD_FILE, MANIFEST_FILE
from slipkit.runtime.cli import main

CARD = "# Model card: linear\n\n- Licence: MIT\n- p99 12 us\n"


def _bundle(root: Path, card: str | None) -> Path:
    return write_bundle(
        root / "b", linear_graph(np.ones(12), 0.0), manifest(12), card=card
    )


def test_card_is_listed_checked_and_read_back(tmp_path: Path) -> None:
    """write_bundle lists MODEL_CARD.md in files with its sha256; Bundle.card() returns it."""
    path = _bundle(tmp_path, CARD)
    files = json.loads((path / MANIFEST_FILE).read_text())["files"]
    assert {"model.onnx", CARD_FILE} == set(files)
    assert CARD == load_bundle(path).card()
    assert CARD == (path / CARD_FILE).read_text(encoding="utf-8")


def test_bundle_without_a_card_loads_and_has_none(tmp_path: Path) -> None:
    path = _bundle(tmp_path, None)
    assert not (path / CARD_FILE).exists()
    assert load_bundle(path).card() is None


def test_edited_card_fails_the_load(tmp_path: Path) -> None:
    path = _bundle(tmp_path, CARD)
    (path / CARD_FILE).write_text(CARD.replace("MIT", "public domain"))
    with pytest.raises(BundleError, match=r"MODEL_CARD\.md: sha256 .* does not match"):
        load_bundle(path)


def test_card_edited_after_the_load_is_refused(tmp_path: Path) -> None:
    """Bundle.card() checks the sha256 again as it reads."""
    path = _bundle(tmp_path, CARD)
    bundle = load_bundle(path)
    (path / CARD_FILE).write_text(CARD + "- accuracy 100 %\n")
    with pytest.raises(BundleError, match="the card changed"):
        bundle.card()


def test_cli_card_prints_it_and_exits_0(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _bundle(tmp_path, CARD)
    with pytest.raises(SystemExit) as exc:
        main([str(path), "--card"])
    assert 0 == exc.value.code
    assert CARD == capsys.readouterr().out


def test_cli_card_escapes_control_characters(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A card cannot send a terminal escape sequence: controls print as \\xNN."""
    path = _bundle(tmp_path, "# card\x1b[2J\tok\n")
    with pytest.raises(SystemExit) as exc:
        main([str(path), "--card"])
    assert 0 == exc.value.code
    assert "# card\\x1b[2J\tok\n" == capsys.readouterr().out


def test_cli_card_of_a_bundle_without_one_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _bundle(tmp_path, None)
    with pytest.raises(SystemExit) as exc:
        main([str(path), "--card"])
    assert 2 == exc.value.code
    captured = capsys.readouterr()
    assert "" == captured.out
    err = captured.err.strip()
    assert 1 == len(err.splitlines())
    assert err.startswith("slipkit-run: error: ")
    assert f"{CARD_FILE}: is missing" in err


def test_cli_card_of_an_edited_card_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _bundle(tmp_path, CARD)
    (path / CARD_FILE).write_text(CARD + "edited\n")
    with pytest.raises(SystemExit) as exc:
        main([str(path), "--card"])
    assert 2 == exc.value.code
    assert "MODEL_CARD.md: sha256" in capsys.readouterr().err


def test_cli_card_is_for_one_bundle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _bundle(tmp_path, CARD)
    with pytest.raises(SystemExit) as exc:
        main(["--stream", f"a={path}", "--card"])
    assert 2 == exc.value.code
    assert "--card" in capsys.readouterr().err
