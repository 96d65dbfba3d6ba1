"""A dataset's ``meta.json``: every field of its files described (dtype, shape, units,
conventions), the cameras' conventions, the mask's ids, and the train/valid/test split.

A run's split is a function of the split seed, its parameters and (for a sampled sweep, whose
run i always draws the same parameters) its id, through SHA-256: it does not change when the
sweep is resumed, nor when more samples or grid values are added (a grid run keeps its split
with its parameters, whatever its new id).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from ..errors import ClothsimError

__all__ = ["SPLITS", "DEFAULT_FRACTIONS", "NODE_NORMAL", "NODE_HANDLE", "parse_split", "split_of", "describe"]

SPLITS = ("train", "valid", "test")
DEFAULT_FRACTIONS = (0.8, 0.1, 0.1)
# MeshGraphNets' NodeType codes: NORMAL 0, OBSTACLE 1, AIRFOIL 2, HANDLE 3, INFLOW 4, OUTFLOW 5,
# WALL_BOUNDARY 6. A cloth has free points and pinned ones (handles).
NODE_NORMAL, NODE_HANDLE = 0, 3
META = "meta.json"
META_FORMAT = "clothsim-dataset/1"


def parse_split(text: str | tuple[float, ...] | list[float] | None) -> tuple[float, float, float]:
    """``"0.8,0.1,0.1"`` (or three numbers) -> fractions of train, valid, test summing to 1."""
    if text is None:
        return DEFAULT_FRACTIONS
    items = text.split(",") if isinstance(text, str) else list(text)
    try:
        values = tuple(float(x) for x in items)
    except (TypeError, ValueError):
        raise ClothsimError(f"--split: expected three fractions TRAIN,VALID,TEST, got {text!r}") from None
    if len(values) != 3 or any(not (0.0 <= v <= 1.0) for v in values) or abs(sum(values) - 1.0) > 1e-9:
        raise ClothsimError(f"--split: expected three fractions in 0..1 summing to 1 (train,valid,test), got {text!r}")
    return values  # type: ignore[return-value]


def split_of(run_id: str, params: dict[str, Any], sampled: bool, fractions: tuple[float, float, float],
             seed: int) -> str:
    """The split of one run: SHA-256 of (seed, params, id if sampled) read as a number in [0, 1),
    against the cumulative fractions."""
    key = json.dumps([seed, params, run_id if sampled else None], sort_keys=True, separators=(",", ":"))
    u = int.from_bytes(hashlib.sha256(key.encode("utf-8")).digest()[:8], "big") / 2.0**64
    if u < fractions[0]:
        return "train"
    if u < fractions[0] + fractions[1]:
        return "valid"
    return "test"


def _f(dtype: str, shape: str, units: str, doc: str, **more: Any) -> dict[str, Any]:
    return {"dtype": dtype, "shape": shape, "units": units, "doc": doc, **more}


def describe(definition: dict[str, Any], runs: list[Any], fractions: tuple[float, float, float], split_seed: int,
             mask_ids: list[dict[str, Any]], points: tuple[int, int]) -> dict[str, Any]:
    """The whole ``meta.json`` of a dataset whose runs are ``runs`` (params.Run)."""
    sampled = definition.get("samples") is not None
    nw, nh = points
    run_fields = {
        "positions": _f("float32", "(T, N, 3)", "m", "the cloth's points at the sampled frames, world space, "
                        "y up; point (x, y) of the nw x nh grid is row y * nw + x"),
        "world_pos": _f("float32", "(T, N, 3)", "m", "MeshGraphNets' name for positions (the same member)",
                        stored_as="positions"),
        "frames": _f("int64", "(T,)", "frame", "the sampled frame numbers: 0, every, 2 every, ..., and the last"),
        "faces": _f("int32", "(F, 3)", "index", "the cloth's triangles, counter-clockwise seen from the front "
                    "(the side the normal points to); F = 2 (nw-1)(nh-1)"),
        "cells": _f("int32", "(F, 3)", "index", "MeshGraphNets' name for faces (the same values)"),
        "uv": _f("float32", "(N, 2)", "1", "texture coordinates in [0, 1]: u along x, v along y"),
        "mesh_pos": _f("float32", "(N, 2)", "m", "MeshGraphNets' rest-state 2-D coordinates: uv times (width, height)"),
        "node_type": _f("int32", "(N,)", "code", "MeshGraphNets' NodeType: 0 NORMAL (a free point), 3 HANDLE "
                        "(a pinned point, moved by the scene's pin motion if any)",
                        codes={"NORMAL": NODE_NORMAL, "HANDLE": NODE_HANDLE}),
        "pinned": _f("bool", "(N,)", "1", "the pinned points (node_type == 3)"),
        "scene": _f("str (0-d)", "()", "JSON", "the run's full resolved scene"),
    }
    meta: dict[str, Any] = {
        "format": META_FORMAT,
        "sweep": "sweep.json",
        "manifest": "manifest.jsonl (one JSON line per finished run; the last line of a run counts)",
        "frames_per_second": None,
        "grid": {"nw": nw, "nh": nh, "N": nw * nh},
        "run_file": {"path": "runs/<id>.npz", "fields": run_fields},
        "splits": {
            "fractions": dict(zip(SPLITS, fractions)), "seed": split_seed,
            "rule": "SHA-256 of the JSON [seed, params, id if the sweep is sampled else null] (sorted keys, "
                    "no spaces); its first 8 bytes big-endian / 2**64 against the cumulative fractions",
            "runs": {s: [r.id for r in runs if split_of(r.id, r.params, sampled, fractions, split_seed) == s]
                     for s in SPLITS},
        },
    }
    views = int(definition.get("views") or 0)
    if views:
        w, h = definition["size"]
        channels = definition["channels"]
        vf: dict[str, Any] = {}
        if "rgb" in channels:
            vf["rgb"] = _f("uint8 PNG", f"({h}, {w}, 3) per file", "sRGB", "the look's image (shader "
                           f"{definition.get('shader') or 'of the scene'}), one file per view and sampled frame",
                           path="runs/<id>/rgb_v<view>_<frame:05d>.png")
        if "depth" in channels:
            vf["depth"] = _f("float32", f"(V, T, {h}, {w})", "m", "distance along the optical axis (OpenCV's z) "
                             "of the surface at the pixel's centre; 0 on the background", member="depth")
        if "normal" in channels:
            vf["normal"] = _f("float16", f"(V, T, {h}, {w}, 3)", "1", "unit world-space normal of the side seen "
                              "(the cloth's mesh normal on its front, its negation on its back); 0 on the background",
                              member="normal")
        if "mask" in channels:
            vf["mask"] = _f("uint8", f"(V, T, {h}, {w})", "id", "segmentation: 0 background, 1 the cloth's front "
                            "(the side its normal points to), 2 its back, 3.. a collider (see mask_ids)",
                            member="mask")
        if "flow" in channels:
            vf["flow"] = _f("float32", f"(V, T-1, {h}, {w}, 2)", "pixel", "optical flow from sampled frame t to "
                            "t+1 on the cloth: where the surface point at the pixel projects at t+1 minus where it "
                            "projects at t, (x right, y down); 0 off the cloth", member="flow")
        meta["views"] = {
            "count": views, "size": [w, h], "channels": channels, "folder": "runs/<id>/",
            "arrays": "runs/<id>/channels.npz (compressed npz; members named below)",
            "cameras": "runs/<id>/cameras.json: a list of V cameras (fixed for the whole run)",
            "cameras_from": definition.get("cameras_from"),
            "fields": vf,
            "mask_ids": [{"id": 0, "kind": "background"}, {"id": 1, "kind": "cloth front"},
                         {"id": 2, "kind": "cloth back"}, *mask_ids],
            "conventions": {
                "pixel": "(u, v) = (column, row), origin at the top-left pixel's centre, v down",
                "K": "OpenCV intrinsics [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], cx = W/2 - 0.5, cy = H/2 - 0.5",
                "world_to_camera_opencv": "4x4 [R | t]: x_cam = R x_world + t; camera x right, y down, z forward",
                "camera_to_world_opencv": "its inverse",
                "view_opengl": "4x4 world -> eye: x right, y up, looking down -z (= diag(1, -1, -1, 1) @ "
                               "world_to_camera_opencv)",
                "projection_opengl": "4x4 eye -> clip, depth -1..1 between near and far; NDC y up (image row 0 "
                                     "is NDC y = +1)",
                "world": "metres, y up (the scene file's frame)",
            },
        }
    return meta
