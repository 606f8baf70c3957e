"""Reading ``manifest.json`` safely: bounded JSON and one declared schema.

The schema is ``slipkit/data/schema/dataset-manifest.schema.json`` (JSON Schema draft
2020-12, printed in ``docs/dataset-format.md``), checked with the ``jsonschema``
package. Two types are stricter than JSON Schema's: an ``integer`` must be a JSON
integer (JSON Schema accepts ``1.0``) and a ``number`` a finite one (Python's JSON
reader accepts ``NaN`` and ``Infinity``); ``true`` is never a number (jsonschema
already refuses it). The first error (``jsonschema.exceptions.best_match``) becomes
one line naming the field path: ``streams.force.rate_hz: expected a positive number
(Hz) for a sampled stream, got true``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from functools import cache
from importlib import resources
from typing import Any

import jsonschema
from jsonschema.exceptions import ValidationError, best_match

from slipkit.errors import DatasetError

#: Largest manifest read, bytes. A manifest lists streams, labels and checksums: a few
#: kB; 64 MiB leaves room for huge provenance while refusing a stray data file.
MAX_MANIFEST_BYTES = 64 * 2**20
#: Deepest JSON nesting read (objects and lists). slipkit writes depth <= ~8 (the
#: resolved scene config in the provenance); Python's parser would recurse to ~1000.
MAX_DEPTH = 64
SCHEMA_RESOURCE = "schema/dataset-manifest.schema.json"
_PLAIN_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _is_integer(_checker: Any, value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(_checker: Any, value: Any) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return True  # math.isfinite overflows on ints beyond float range
    return isinstance(value, float) and math.isfinite(value)


_Validator = jsonschema.validators.extend(
    jsonschema.Draft202012Validator,
    type_checker=jsonschema.Draft202012Validator.TYPE_CHECKER.redefine_many(
        {"integer": _is_integer, "number": _is_number}
    ),
)


@cache
def manifest_schema() -> dict[str, Any]:
    """The dataset manifest's JSON Schema (draft 2020-12), as shipped in the package."""
    text = resources.files("slipkit.data").joinpath(SCHEMA_RESOURCE).read_text("utf-8")
    schema: dict[str, Any] = json.loads(text)
    return schema


@cache
def _validator() -> Any:
    return _Validator(manifest_schema())


def _no_duplicate_keys(where: str) -> Any:
    def hook(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        obj: dict[str, Any] = {}
        for key, value in pairs:
            if key in obj:
                # json.loads keeps the last value silently; other readers keep the
                # first. Either way one of the two is ignored, so refuse.
                raise DatasetError(
                    where,
                    f"key {key!r} appears twice in one JSON object; each field once",
                )
            obj[key] = value
        return obj

    return hook


def _depth_exceeds(obj: Any, limit: int) -> bool:
    """Whether ``obj`` nests objects and lists deeper than ``limit`` (iterative)."""
    stack: list[tuple[Any, int]] = [(obj, 1)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict | list):
            if depth > limit:
                return True
            children: Iterable[Any] = node.values() if isinstance(node, dict) else node
            stack.extend((child, depth + 1) for child in children)
    return False


def parse_manifest_bytes(data: bytes, where: str) -> Any:
    """Parse manifest bytes as UTF-8 JSON: no duplicate keys, nesting <= MAX_DEPTH.

    Raises
    ------
    DatasetError
        Naming ``where``: not UTF-8, not JSON, a duplicate key, too deep.
    """
    if len(data) > MAX_MANIFEST_BYTES:
        raise DatasetError(
            where,
            f"is {len(data)} bytes; a manifest is at most {MAX_MANIFEST_BYTES} bytes",
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DatasetError(where, f"is not UTF-8 text ({exc})") from exc
    try:
        obj = json.loads(text, object_pairs_hook=_no_duplicate_keys(where))
    except DatasetError:
        raise
    except RecursionError as exc:
        raise DatasetError(
            where,
            f"nests JSON deeper than Python can parse; at most {MAX_DEPTH} levels",
        ) from exc
    except ValueError as exc:  # JSONDecodeError, and ints over 4300 digits
        raise DatasetError(where, f"is not valid JSON ({exc})") from exc
    if _depth_exceeds(obj, MAX_DEPTH):
        raise DatasetError(
            where, f"nests JSON objects or lists deeper than {MAX_DEPTH} levels"
        )
    return obj


def field_path(path: Iterable[Any]) -> str:
    """``['streams', 'force', 'rate_hz']`` -> ``streams.force.rate_hz``;
    ``['files', 'trials.parquet']`` -> ``files["trials.parquet"]``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        elif _PLAIN_KEY.match(str(part)):
            out += f".{part}" if out else str(part)
        else:  # a key with dots or spaces (files["trials.parquet"]) stays readable
            out += f"[{json.dumps(part)}]"
    return out


def _show(value: Any) -> str:
    """A JSON value as the message quotes it (short)."""
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**15:
        return f"an integer of {len(str(abs(value)))} digits"
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


_TYPES = {
    "object": "an object",
    "array": "a list",
    "string": "text",
    "integer": "an integer",
    "number": "a number",
    "boolean": "true or false",
    "null": "null",
}


def _describe(schema: Any) -> str:
    """What a subschema expects, in words: its ``title``, else from its keywords."""
    if not isinstance(schema, dict):
        return "nothing here"
    if "title" in schema:
        return str(schema["title"])
    if "const" in schema:
        return json.dumps(schema["const"])
    if "enum" in schema:
        return "one of " + ", ".join(json.dumps(v) for v in schema["enum"])
    types = schema.get("type", [])
    types = [types] if isinstance(types, str) else list(types)
    words = " or ".join(_TYPES.get(t, t) for t in types) or "a valid value"
    bounds = []
    for key, sign in (
        ("minimum", ">="),
        ("exclusiveMinimum", ">"),
        ("maximum", "<="),
        ("exclusiveMaximum", "<"),
    ):
        if key in schema:
            bounds.append(f"{sign} {schema[key]}")
    if bounds:
        words += " " + " and ".join(bounds)
    if schema.get("minLength", 0) >= 1:
        words = "non-empty " + words
    return words


def _message(error: ValidationError) -> str:
    where = field_path(error.absolute_path)
    prefix = f"{where}: " if where else ""
    keyword = error.validator
    if keyword == "required" and isinstance(error.instance, dict):
        missing = [k for k in error.validator_value if k not in error.instance]
        return f"{prefix}missing field {missing[0]!r}"
    if keyword == "additionalProperties" and isinstance(error.instance, dict):
        known = set(error.schema.get("properties", {}))
        extra = sorted(str(k) for k in error.instance if k not in known)
        return f"{prefix}unexpected field {extra[0]!r}; expected fields {sorted(known)}"
    if "propertyNames" in error.relative_schema_path:
        return (
            f"{prefix}key {_show(error.instance)}: expected {_describe(error.schema)}"
        )
    if keyword == "uniqueItems":
        return f"{prefix}expected {_describe(error.schema)}, got a repeated entry"
    return f"{prefix}expected {_describe(error.schema)}, got {_show(error.instance)}"


def validate_manifest(manifest: Any, where: str) -> None:
    """Check a parsed manifest against the schema.

    Raises
    ------
    DatasetError
        ``<where>: <field path>: expected <what>, got <value>`` for the most relevant
        error (jsonschema's ``best_match``).
    """
    error = best_match(_validator().iter_errors(manifest))
    if error is not None:
        raise DatasetError(where, _message(error))
