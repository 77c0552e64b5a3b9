"""Back-projection + voxel fusion and rendering, frames per second at 640×480.

    python benchmarks/mapping.py [--reps 30] [--threads N]

Frames are the paper home's survey views (rendered once, ground-truth masks of static classes).
Fusion runs three ways on the same frames: torch (the mapper's code), torch with one CPU thread,
and a plain numpy version (np.add.at into a numpy vote array). Times are medians per frame; the
machine is shared, so medians rather than means. Target: ≥ 30 fps for torch fusion on this CPU.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

from objsearch.agent.camera_frames import RGBDFrame, backproject
from objsearch.agent.categories import Category
from objsearch.agent.detect import GroundTruthDetector
from objsearch.agent.mapping import (
    GridSpec,
    MappingConfig,
    VoxelGrid,
    backproject_labels,
    label_image,
    survey_poses,
)
from objsearch.agent.session import load_context
from objsearch.sim.render import SimulatedCamera


def fuse_numpy(votes: np.ndarray, spec: GridSpec, frame: RGBDFrame, labels: np.ndarray) -> None:
    mask = labels >= 0
    pts = backproject(frame, mask)
    lab = labels[mask & (frame.depth > 0)]
    idx = np.floor((pts - np.asarray(spec.origin, np.float32)) / spec.voxel).astype(np.int64)
    inside = ((idx >= 0) & (idx < np.asarray(spec.shape))).all(axis=1)
    idx, lab = idx[inside], lab[inside]
    np.add.at(votes, (idx[:, 0], idx[:, 1], idx[:, 2], lab), 1)


def median_ms(fn, items, reps: int) -> float:  # type: ignore[no-untyped-def]
    times = []
    for i in range(reps):
        item = items[i % len(items)]
        t0 = time.perf_counter()
        fn(item)
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reps", type=int, default=32)
    ap.add_argument("--room", default="kitchen")
    args = ap.parse_args()
    ctx = load_context("paper")
    classes = ctx.vocabulary.names(Category.STATIC)
    camera = SimulatedCamera(ctx.home)
    poses = survey_poses(ctx.navmap, [args.room], 4)
    detector = GroundTruthDetector(frozenset(classes))

    render_ms = median_ms(lambda rp: camera.frame(rp[1], rp[0]), poses, args.reps)
    frames = [camera.frame(p, r) for r, p in poses]
    labels = [label_image(detector.detect(f), classes, f.intrinsics.shape) for f in frames]
    labelled = statistics.median(float((lab >= 0).mean()) for lab in labels)
    spec = GridSpec.around(ctx.navmap.viewpoints(args.room), MappingConfig())
    items = list(zip(frames, labels, strict=True))

    cpu = torch.device("cpu")
    grid = VoxelGrid(spec, len(classes), cpu)
    rays = torch.from_numpy(frames[0].intrinsics.rays().copy())

    def fuse_torch(item: tuple[RGBDFrame, np.ndarray]) -> None:
        frame, lab = item
        pts, lab_t = backproject_labels(
            torch.from_numpy(frame.depth),
            torch.from_numpy(lab),
            rays,
            torch.from_numpy(frame.T_map_camera.astype(np.float32)),
        )
        grid.integrate(pts, lab_t)

    votes = np.zeros((*spec.shape, len(classes)), dtype=np.int32)
    default_threads = torch.get_num_threads()
    fuse_torch(items[0])  # warm-up
    torch_ms = median_ms(fuse_torch, items, args.reps)
    torch.set_num_threads(1)
    torch1_ms = median_ms(fuse_torch, items, args.reps)
    torch.set_num_threads(default_threads)
    numpy_ms = median_ms(lambda it: fuse_numpy(votes, spec, it[0], it[1]), items, args.reps)

    print(
        f"640×480, {len(frames)} survey views of the {args.room}, median {labelled:.0%} of "
        f"pixels labelled; grid {spec.shape} × {len(classes)} classes; {args.reps} reps"
    )
    print(f"{'step':42} {'median ms':>10} {'fps':>8} {'vs numpy':>9}")
    for name, ms in (
        (f"fusion, torch ({default_threads} threads)", torch_ms),
        ("fusion, torch (1 thread)", torch1_ms),
        ("fusion, numpy (np.add.at)", numpy_ms),
    ):
        print(f"{name:42} {ms:10.2f} {1000 / ms:8.1f} {numpy_ms / ms:8.1f}×")
    print(f"{'rendering (numpy ray casting)':42} {render_ms:10.2f} {1000 / render_ms:8.1f}")
    best = min(torch_ms, torch1_ms)
    print(f"target ≥ 30 fps for torch fusion: {'met' if 1000 / best >= 30 else 'NOT met'}")


if __name__ == "__main__":
    main()
