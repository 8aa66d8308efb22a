"""A run's result folder: what `flybo run` leaves in `--out`, and what a worker uploads.

The episode writes the recording itself (`run_episode(..., recording_path=folder / RECORDING)`);
`write_result_folder` adds the metrics and the reconstructed mesh beside it. The format of each
file is in `docs/result-format.md` and `docs/recording.md`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from sim.result import EpisodeResult

RECORDING = "recording.npz"
MESH = "mesh.ply"
RESULT = "result.json"


class ResultFolderError(OSError):
    """A file of the result folder could not be written."""


_EMPTY_PLY = ("ply\nformat ascii 1.0\ncomment no surface was reconstructed\n"
              "element vertex 0\nproperty double x\nproperty double y\nproperty double z\n"
              "element face 0\nproperty list uchar int vertex_indices\nend_header\n")


def write_result_folder(result: EpisodeResult, folder: Path,
                        record: dict[str, Any] | None = None) -> dict[str, Path]:
    """Write `result.json` (with the run's reproducibility `record`, `flybo/record.py`) and
    `mesh.ply` of `result` into `folder` (which holds the episode's recording); returns the
    folder's three files by kind: recording, mesh, result. A run that reconstructed no surface
    gets an empty mesh file (Open3D refuses to write one), its metrics scored as such.

    Raises:
        ResultFolderError: the mesh writer failed.
    """
    from sim.open3d_any import o3d  # Open3D: only where results are written

    mesh_path = folder / MESH
    if len(result.mesh_vertices) == 0:
        mesh_path.write_text(_EMPTY_PLY)
    else:
        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(np.asarray(result.mesh_vertices, dtype=np.float64)),
            o3d.utility.Vector3iVector(np.asarray(result.mesh_triangles, dtype=np.int32)))
        if not o3d.io.write_triangle_mesh(str(mesh_path), mesh, write_ascii=False):
            raise ResultFolderError(f"could not write {mesh_path}")
    payload = result.to_json()
    if record is not None:
        payload["reproducibility"] = record
    result_path = folder / RESULT
    result_path.write_text(json.dumps(payload, indent=2) + "\n")
    return {"recording": folder / RECORDING, "mesh": mesh_path, "result": result_path}
