"""The gripper-PC runtime: load an ONNX bundle and decide slip on every sensor frame.

Imports only the standard library, numpy and onnxruntime (and ``slipkit.errors``,
standard library only), so ``pip install 'slipkit[runtime]'`` is enough to run it;
``slipkit-run --report-modules`` shows which heavy libraries a run loaded (none).

Modules: :mod:`~slipkit.runtime.bundle` (format, :func:`load_bundle`,
:func:`write_bundle`), :mod:`~slipkit.runtime.preprocessing` (the op registry),
:mod:`~slipkit.runtime.session` (session options), :mod:`~slipkit.runtime.loop`
(:class:`StreamLoop`), :mod:`~slipkit.runtime.sources` (replay, UDP),
:mod:`~slipkit.runtime.sinks` (decisions out: UDP datagrams,
JSON lines, :class:`DecisionReceiver`), :mod:`~slipkit.runtime.tuning` (:func:`choose_session`), :mod:`~slipkit.runtime.cli`
(``slipkit-run``), :mod:`~slipkit.runtime.modules` (the import check).
"""

from slipkit.runtime.bundle import (
    FORMAT,
    MANIFEST_FILE,
    MODEL_FILE,
    REPLAY_FILE,
    SCHEMA_VERSION,
    SIGNATURE_FILE,
    Bundle,
    Manifest,
    load_bundle,
    read_key,
    validate_manifest,
    write_bundle,
)
from slipkit.runtime.errors import BundleError, FrameError
from slipkit.runtime.loop import LoopResult, StreamLoop, latency_summary
from slipkit.runtime.modules import HEAVY_MODULES, heavy_modules_loaded
from slipkit.runtime.preprocessing import OPS, register_op
from slipkit.runtime.session import SessionSpec
from slipkit.runtime.sinks import (
    Decision,
    DecisionReceiver,
    JsonlSink,
    UdpSink,
    pack_decision,
    unpack_decision,
)
from slipkit.runtime.sources import (
    ReplaySource,
    UdpSender,
    UdpSource,
    decode_frame,
    encode_frame,
    load_replay,
)
from slipkit.runtime.tuning import choose_session

__all__ = [
    "FORMAT",
    "HEAVY_MODULES",
    "MANIFEST_FILE",
    "MODEL_FILE",
    "OPS",
    "REPLAY_FILE",
    "SCHEMA_VERSION",
    "SIGNATURE_FILE",
    "Bundle",
    "BundleError",
    "Decision",
    "DecisionReceiver",
    "FrameError",
    "JsonlSink",
    "LoopResult",
    "Manifest",
    "ReplaySource",
    "SessionSpec",
    "StreamLoop",
    "UdpSender",
    "UdpSink",
    "UdpSource",
    "choose_session",
    "decode_frame",
    "encode_frame",
    "heavy_modules_loaded",
    "latency_summary",
    "load_bundle",
    "load_replay",
    "pack_decision",
    "read_key",
    "register_op",
    "unpack_decision",
    "validate_manifest",
    "write_bundle",
]
