"""The ``sweep`` subcommand: many runs of a scene with parameters varied."""

from __future__ import annotations

import argparse

from ..commands import add_command, add_output
from ..errors import ClothsimError


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim sweep``."""
    p = add_command(
        sub, "sweep",
        "run a scene over a grid or a sample of parameters: a labelled contact sheet (.png) or a dataset folder",
        "Run SCENE once per parameter set. Several --set make the full grid (run_00000, run_00001, ... in "
        "grid order, last --set fastest); --samples N --seed S draws N runs instead. OUT ending in .png is a "
        "contact sheet of each run's last frame (or of each frame listed in --frames) as 'clothsim render' "
        "draws it; any other OUT is a dataset folder: manifest.jsonl and runs/<id>.npz (positions every "
        "--every frames; with --views, images, depth, normals, masks, flow and cameras per run; meta.json describes "
        "every field and the train/valid/test split), resumed by re-running the same command. Every run's scene "
        "is validated first.", scene=None)
    p.add_argument("--set", dest="sets", action="append", required=True, metavar="FIELD=VALUES",
                   help="a dotted field (cloth.ks, simulation.simulation_steps, sphere.1.radius, "
                        "render.light.intensity) and comma-separated JSON values; with --samples also "
                        "uniform:A:B or loguniform:A:B")
    add_output(p, "a .png contact sheet, or a dataset folder")
    p.add_argument("--frames", default="90", metavar="N",
                   help="frames to simulate (default 90); for a .png a comma-separated list draws one cell per frame")
    p.add_argument("--every", type=int, default=1, metavar="K", help="dataset: keep positions every K frames (default 1)")
    p.add_argument("--shader", help="look of the images (default: the scene's, else phong)")
    p.add_argument("--size", metavar="WxH", help="image size of a cell, video frame or view (default 256x256)")
    p.add_argument("--samples", type=int, metavar="N", help="draw N runs at random instead of the grid (needs --seed)")
    p.add_argument("--seed", type=int, metavar="S", help="seed of --samples: run i's parameters depend on S and i only")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: one per core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on an existing Dask cluster, e.g. tcp://host:8786 (pip install 'clothsim[cluster]')")
    p.add_argument("--video", action="store_true", help="dataset: also write runs/<id>.mp4 of the sampled frames")
    # (the dataset's options: alike in shape, not in meaning, to render's, as argparse declarations are)
    p.add_argument("--views", type=int, default=0, metavar="N",
                   help="dataset: draw every sampled frame from N fixed cameras (the scene's render.views, else "
                        "drawn around the cloth from the run's seed) into runs/<id>/")
    p.add_argument("--channels", metavar="LIST",
                   help="with --views: comma-separated channels of rgb,depth,normal,mask,flow (default all)")
    # (option declarations: the duplicate-code scan pairs these lines with render's by shape alone)
    p.add_argument("--write-in-workers", action="store_true",
                   help="dataset: each worker writes its runs' files straight into OUT (a folder every worker "
                        "reaches); an fsspec URL as OUT (memory://, s3://...) is always written so")
    p.add_argument("--split", metavar="TRAIN,VALID,TEST",
                   help="dataset: fractions of the train/valid/test split in meta.json (default 0.8,0.1,0.1)")
    p.add_argument("--split-seed", type=int, default=0, metavar="S", help="dataset: seed of the split (default 0)")
    p.set_defaults(func=run_sweep, kernels=False)  # the workers run them


def run_sweep(args: argparse.Namespace) -> int:
    """Body of ``clothsim sweep``: exit 1 if any run failed."""
    from ..render.settings import SHADERS
    from . import params
    from .api import sweep

    if args.shader is not None and args.shader not in SHADERS:
        raise ClothsimError(f"--shader: unknown shader {args.shader!r} (expected one of: {', '.join(SHADERS)})")
    space: dict[str, list] = {}
    for text in args.sets:
        field, values = params.parse_set(text)
        if field in space:
            raise ClothsimError(f"--set {field}: given twice")
        space[field] = values
    frames = args.frames.split(",") if "," in args.frames else args.frames
    try:
        frames = [int(f) for f in frames] if isinstance(frames, list) else int(frames)
    except ValueError:
        raise ClothsimError(f"--frames: expected a count or a comma-separated list, got {args.frames!r}") from None
    if args.scheduler is not None:
        from .engines import import_distributed

        import_distributed()
    records = sweep(args.scene, space, args.output, frames=frames, every=args.every, samples=args.samples,
                    seed=args.seed, shader=args.shader, size=args.size, workers=args.workers,
                    scheduler=args.scheduler, video=args.video, views=args.views, channels=args.channels,
                    split=args.split, split_seed=args.split_seed, write_in_workers=args.write_in_workers,
                    progress=True, report=True)
    return 1 if any(r["status"] == "failed" for r in records) else 0
