"""Reading and writing results: TUM and KITTI trajectories, landmark CSV, JSON, atomic
output folders and fresh default ones."""

from slamkit.io.folders import atomic_folder, fresh_folder, same_folder, write_json
from slamkit.io.kitti import format_kitti, read_kitti, read_kitti_matrices, write_kitti
from slamkit.io.landmarks import format_landmarks_csv, read_landmarks_csv, write_landmarks_csv
from slamkit.io.tum import format_tum, read_tum, read_tum_matrices, write_tum

__all__ = [
    "atomic_folder",
    "format_kitti",
    "format_landmarks_csv",
    "format_tum",
    "fresh_folder",
    "read_kitti",
    "read_kitti_matrices",
    "read_landmarks_csv",
    "read_tum",
    "read_tum_matrices",
    "same_folder",
    "write_json",
    "write_kitti",
    "write_landmarks_csv",
    "write_tum",
]
