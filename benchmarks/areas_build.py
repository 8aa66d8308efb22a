"""Build cost of the built-in areas, their statistics against the paper's Table 1, and a short
Classic flight on each.

    taskset -c 0 .venv/bin/python benchmarks/areas_build.py [--seconds 60] [--areas a,b]

1. Build: every area from an empty cache (a fresh temporary FLYBO_CACHE_DIR): mesh generation,
   ground truth (observable voxels and the 2 cm surface cloud) and thumbnails.
2. Load: the same areas again from the disk cache in this process, after dropping the in-memory
   caches (mesh generation plus reading the ground truth).
3. Statistics measured from the mesh and ground truth beside Table 1.
4. Classic for ``--seconds`` simulated seconds at the "exact" preset (seed 0): collisions,
   coverage, how the episode ended.

pybullet's ``createCollisionShape`` refuses meshes passed as data beyond 131072 vertices or
524288 indices (about 175k triangles), which OFFICES C and FACILITY B and C exceed. Until the
simulator loads such meshes another way, this script routes those calls through a temporary OBJ
file, which pybullet loads without that limit (the same triangles, one static body).

Outdoor, a camera above 3 m looking out of the area sees nothing within its 5 m range; Open3D's
TSDF integration aborts on a frame that touches no TSDF block ("No block is touched"), so this
script skips those frames for the TSDF (the occupancy map still records the free rays). Both
are workarounds for the simulator.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import peak_rss_mib, print_table, write_json

# pybullet's shared-memory command limits for mesh data (B3_MAX_NUM_VERTICES, _INDICES).
PYBULLET_MAX_VERTICES = 131072
PYBULLET_MAX_INDICES = 524288


def _load_large_meshes_from_files() -> None:
    """Make pybullet.createCollisionShape accept meshes beyond its data limits (see above)."""
    from sim.world import pybullet

    original = pybullet.createCollisionShape

    def create(shape_type: int, **kwargs: Any) -> int:
        vertices, indices = kwargs.get("vertices"), kwargs.get("indices")
        if vertices is None or indices is None or (len(vertices) <= PYBULLET_MAX_VERTICES
                                                   and len(indices) <= PYBULLET_MAX_INDICES):
            return int(original(shape_type, **kwargs))
        fd, name = tempfile.mkstemp(suffix=".obj")
        try:
            with os.fdopen(fd, "w") as f:
                np.savetxt(f, np.asarray(vertices), fmt="v %.6f %.6f %.6f")
                np.savetxt(f, np.asarray(indices).reshape(-1, 3) + 1, fmt="f %d %d %d")
            rest = {k: v for k, v in kwargs.items() if k not in ("vertices", "indices")}
            return int(original(shape_type, fileName=name, **rest))
        finally:
            os.unlink(name)

    pybullet.createCollisionShape = create


def _skip_empty_tsdf_frames() -> None:
    """Skip TSDF integration of depth frames that touch no TSDF block (see above)."""
    from sim.tsdf import TsdfVolume

    original = TsdfVolume.integrate

    def integrate(self: TsdfVolume, depth: np.ndarray, pose: Any) -> None:
        try:
            original(self, depth, pose)
        except RuntimeError as exc:
            if "No block is touched" not in str(exc):
                raise

    TsdfVolume.integrate = integrate  # type: ignore[method-assign]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--areas", default=None, help="comma-separated names (default: all)")
    args = parser.parse_args()
    cache = tempfile.mkdtemp(prefix="flybo-areas-bench-")
    os.environ["FLYBO_CACHE_DIR"] = cache
    try:
        _measure(args.seconds, args.areas)
    finally:
        shutil.rmtree(cache, ignore_errors=True)  # about 0.5 GB of ground truth


def _measure(seconds: float, area_list: str | None) -> None:
    """Run the four measurements (see the module docstring) and report them."""
    from areas import area_names, ground_truth, load_area, load_ground_truth, registry
    from areas.ground_truth import ground_truth_path
    from areas.stats import TABLE1, face_order, measure
    from areas.thumbnail import write_thumbnails
    from planners.registry import make
    from sim.config import preset
    from sim.episode import run_episode

    names = area_list.split(",") if area_list else area_names()
    rows: dict[str, dict[str, Any]] = {name: {} for name in names}
    began = time.perf_counter()
    began_cpu = time.process_time()
    for name in names:
        c0 = time.process_time()
        t0 = time.perf_counter()
        area = load_area(name)
        t1 = time.perf_counter()
        truth = load_ground_truth(area)
        t2 = time.perf_counter()
        write_thumbnails(area)
        t3 = time.perf_counter()
        rows[name].update(mesh_s=t1 - t0, ground_truth_s=t2 - t1, thumbnails_s=t3 - t2,
                          build_s=t3 - t0, build_cpu_s=time.process_time() - c0,
                          faces=len(area.triangles),
                          surface_points=len(truth.surface),
                          cache_mib=ground_truth_path(area).stat().st_size / 2**20)
        print(f"built {name} in {t3 - t0:.1f} s", flush=True)
    build_total = time.perf_counter() - began
    build_cpu = time.process_time() - began_cpu

    for name in names:
        registry._loaded.clear()
        ground_truth._memory_cache.clear()
        c0 = time.process_time()
        t0 = time.perf_counter()
        area = load_area(name)
        truth = load_ground_truth(area)
        rows[name]["load_s"] = time.perf_counter() - t0
        rows[name]["load_cpu_s"] = time.process_time() - c0
        stats = measure(area, truth)
        paper = TABLE1[name]
        bounding_error = max(abs(m - p) / p for m, p in zip(stats.bounding, paper.bounding,
                                                             strict=True))
        rows[name].update(
            area_m2=stats.area_m2, volume_m3=stats.volume_m3, bounding=stats.bounding,
            levels=stats.levels, paper=paper.__dict__, bounding_error=bounding_error,
            face_order=face_order(stats.faces),
        )

    _load_large_meshes_from_files()
    _skip_empty_tsdf_frames()
    config = preset("exact")
    for name in names:
        area = load_area(name)
        truth = load_ground_truth(area)
        t0 = time.perf_counter()
        result = run_episode(area, truth, make("classic-v1"), config, 0, planner_name="classic-v1",
                             preset_name="exact", seconds=seconds).to_json()
        rows[name].update(flight_wall_s=time.perf_counter() - t0,
                          collisions=result["collisions"], coverage=result["coverage"],
                          explored_m3=result["explored_volume_m3"],
                          status=f"{result['status']} ({result['reason']})",
                          path_length_m=result["path_length_m"])
        print(f"flew {name}: {rows[name]['status']}, {result['collisions']} collisions", flush=True)

    def size(v: Any) -> str:
        return " x ".join(f"{x:.3g}" for x in v)

    print_table("Build from an empty cache and load from the cache, seconds",
                ["area", "faces", "mesh", "ground truth", "thumbnails", "build", "build CPU",
                 "load", "load CPU", "points (M)", "cache MiB"],
                [[n, f"{r['faces']:,}", f"{r['mesh_s']:.2f}", f"{r['ground_truth_s']:.1f}",
                  f"{r['thumbnails_s']:.1f}", f"{r['build_s']:.1f}", f"{r['build_cpu_s']:.1f}",
                  f"{r['load_s']:.2f}", f"{r['load_cpu_s']:.2f}",
                  f"{r['surface_points'] / 1e6:.1f}", f"{r['cache_mib']:.0f}"]
                 for n, r in rows.items()])
    print(f"total build {build_total:.1f} s wall, {build_cpu:.1f} s CPU, load average "
          f"{os.getloadavg()[0]:.1f}, peak memory {peak_rss_mib():.0f} MiB")
    print_table("Measured statistics / Table 1",
                ["area", "area m²", "volume m³", "bounding m", "err", "levels", "faces"],
                [[n, f"{r['area_m2']:.0f} / {r['paper']['area_m2']:g}",
                  f"{r['volume_m3']:.0f} / {r['paper']['volume_m3']:g}",
                  f"{size(r['bounding'])} / {size(r['paper']['bounding'])}",
                  f"{100 * r['bounding_error']:.1f} %", f"{r['levels']} / {r['paper']['levels']}",
                  f"{r['faces']:,} / {r['paper']['faces']:,}"] for n, r in rows.items()])
    print_table(f"Classic, {seconds:g} simulated s, preset exact, seed 0",
                ["area", "status", "collisions", "coverage", "explored m³", "path m", "wall s"],
                [[n, r["status"], r["collisions"], f"{r['coverage']:.3f}",
                  f"{r['explored_m3']:.0f}", f"{r['path_length_m']:.0f}",
                  f"{r['flight_wall_s']:.0f}"] for n, r in rows.items()])
    path = write_json("areas_build", {"seconds": seconds, "build_total_s": build_total,
                                      "build_cpu_s": build_cpu,
                                      "peak_rss_mib": peak_rss_mib(), "areas": rows})
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
