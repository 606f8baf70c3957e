"""Writing a bundle: the ONNX graph(s), the replay, the model card and the signed
manifest, atomically (a temp folder, then one rename), then loaded back as the gripper PC
would load it."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from slipkit._files import atomic_dir, sha256_bytes, sha256_file
from slipkit.runtime.bundle import _session, load_bundle
from slipkit.runtime.errors import BundleError
from slipkit.runtime.manifest import (
    CARD_FILE,
    DIGEST_FIELD,
    FORMAT,
    MANIFEST_FILE,
    MODEL_FILE,
    PREPARE_FILE,
    REPLAY_FILE,
    SCHEMA_VERSION,
    SIGNATURE_FILE,
    manifest_hmac,
    onnx_dtype,
    sign_manifest,
    validate_manifest,
)
from slipkit.runtime.session import SessionSpec


def _jsonable(value: Any) -> Any:
    """``json.dumps`` default: numpy arrays and scalars become lists and numbers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _describe_outputs(outputs: Any, model: bytes, model_file: str) -> Any:
    """The manifest's ``outputs`` with each one's dtype and shape filled in from the graph.

    Entries that are not ``{name: ...}`` objects, or name no graph output, are left
    as they are for :func:`validate_manifest` and :func:`load_bundle` to name.
    """
    if not isinstance(outputs, list):
        return outputs
    graph = {
        o.name: o for o in _session(model, SessionSpec(), model_file).get_outputs()
    }
    out = []
    for item in outputs:
        if isinstance(item, Mapping) and item.get("name") in graph:
            g = graph[item["name"]]
            item = dict(item)
            item.setdefault("dtype", onnx_dtype(g.type))
            if g.shape is not None and "shape" not in item:
                item["shape"] = [
                    d if isinstance(d, int) and d > 0 else None for d in g.shape
                ]
        out.append(item)
    return out


def write_bundle(
    out: str | Path,
    model: bytes,
    manifest: Mapping[str, Any],
    *,
    replay: tuple[np.ndarray, np.ndarray] | None = None,
    overwrite: bool = False,
    prepare: bytes | None = None,
    key: bytes | None = None,
    card: str | None = None,
) -> Path:
    """Write a bundle atomically: a temporary sibling folder, checked, then renamed.

    Parameters
    ----------
    out : str or Path
        The bundle folder to create (``exports/<name>``).
    model : bytes
        The serialised ONNX graph (``model.SerializeToString()``).
    manifest : mapping
        The manifest without ``files`` and ``manifest_sha256`` (computed here);
        ``format`` and ``schema_version`` are filled in when absent, and so are
        each listed output's ``dtype`` and ``shape`` (read from the graph; a
        symbolic dimension is ``null``). numpy arrays and scalars are written as
        JSON lists and numbers.
    replay : (frames, timestamps), optional
        Recorded frames ``(n, *frame.shape)`` and their times ``(n,)`` in s, written
        as ``replay.npz`` for ``slipkit-run <bundle>`` and session tuning.
    overwrite : bool
        Replace an existing bundle folder (only a bundle: any other folder or file
        under out is refused, as is an out inside a slipkit folder).
    prepare : bytes, optional
        The prepare graph (``prepare.onnx``; the manifest then has ``prepare``).
    key : bytes, optional
        Sign the bundle: ``manifest.hmac`` holds :func:`manifest_hmac` of the
        written ``manifest.json`` under this key.
    card : str, optional
        The model card, written as ``MODEL_CARD.md`` (:data:`CARD_FILE`) and listed
        in ``files`` like the graph.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    BundleError
        When the written bundle does not load (:func:`load_bundle` runs on the
        temporary folder first, so a bad bundle is never left under ``out``).
    """
    # Deferred import: sources imports this module for REPLAY_FILE.
    from slipkit.runtime.sources import check_replay_arrays

    target = Path(out)
    mfile = str(target / MANIFEST_FILE)
    if target.exists() and not overwrite:
        raise BundleError(
            str(target), None, "already exists (pass overwrite=True to replace it)"
        )
    man = dict(manifest)
    man.setdefault("format", FORMAT)
    man.setdefault("schema_version", SCHEMA_VERSION)
    man["files"] = {MODEL_FILE: sha256_bytes(model)}
    if prepare is not None:
        man["files"][PREPARE_FILE] = sha256_bytes(prepare)
    man.pop(DIGEST_FIELD, None)
    man["outputs"] = _describe_outputs(
        man.get("outputs"), model, str(target / MODEL_FILE)
    )
    try:
        # A JSON round trip first: the manifest is checked exactly as it will be read.
        man = json.loads(json.dumps(man, default=_jsonable, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise BundleError(
            mfile, None, f"cannot be written as strict JSON: {exc}"
        ) from None
    checked = validate_manifest(man, mfile)
    with atomic_dir(target, overwrite=overwrite, kind="bundle") as tmp:
        (tmp / MODEL_FILE).write_bytes(model)
        if prepare is not None:
            (tmp / PREPARE_FILE).write_bytes(prepare)
        if replay is not None:
            frames, times = check_replay_arrays(
                np.asarray(replay[0]),
                np.asarray(replay[1]),
                checked.frame.shape,
                str(target / REPLAY_FILE),
            )
            np.savez(tmp / REPLAY_FILE, frames=frames, timestamps=times)
            man["files"][REPLAY_FILE] = sha256_file(tmp / REPLAY_FILE)
        if card is not None:
            data = card.encode("utf-8")
            (tmp / CARD_FILE).write_bytes(data)
            man["files"][CARD_FILE] = sha256_bytes(data)
        # The digest last, over the final content (files included).
        man = sign_manifest(man)
        text = json.dumps(man, indent=2) + "\n"
        (tmp / MANIFEST_FILE).write_text(text, encoding="utf-8")
        if key is not None:
            data = (tmp / MANIFEST_FILE).read_bytes()
            (tmp / SIGNATURE_FILE).write_text(manifest_hmac(data, key) + "\n")
        # the graph, its IO, the preprocessing and the signature, before the rename
        load_bundle(tmp, key=key)
    return target
