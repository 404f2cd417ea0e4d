"""Reads back what Meshcat.StaticHtml() put in replay.html: the viewer commands,
each a msgpack message inlined as a base64 data URL."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import msgpack

_BLOB = re.compile(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]*)"\)')


def replay_commands(path: Path) -> list[dict]:
    text = Path(path).read_text(encoding="utf-8")
    return [
        msgpack.unpackb(base64.b64decode(b), raw=False, strict_map_key=False) for b in _BLOB.findall(text)
    ]


def animation_tracks(commands: list[dict]) -> tuple[float, dict[tuple[str, str], list[dict]]]:
    """(frames per second, {(path, ".property"): keys}) of the one set_animation command."""
    (animation,) = [c for c in commands if c.get("type") == "set_animation"]
    tracks, fps = {}, None
    for item in animation["animations"]:
        fps = item["clip"]["fps"]
        for track in item["clip"]["tracks"]:
            tracks[(item["path"], track["name"])] = track["keys"]
    return fps, tracks
