"""Simulated drives in KITTI's tracking format: the exact inverse of :mod:`dstenv.kitti.readers`.

``dstenv export-kitti --scenario S --frames N --out DIR`` runs the pipeline with the
3-D LIDAR (``lidar.model = "hdl64"``) and writes, for sequence ``SSSS``::

    DIR/training/velodyne/SSSS/FFFFFF.bin   the HDL-64E-like cloud, float32 x, y, z, r
    DIR/training/label_02/SSSS.txt          one row per agent and frame (rules below)
    DIR/training/oxts/SSSS.txt              30 columns: lat, lon, alt, roll, pitch, yaw, ...
    DIR/training/calib/SSSS.txt             P0..P3, R_rect, Tr_velo_cam, Tr_imu_velo

so ``dstenv kitti convert --root DIR`` reads a simulated drive exactly like a real one.

Rig (:func:`sim_calibration`): KITTI's camera intrinsics (sequence 0003) on an ideal,
level mounting: the camera axes are the Velodyne's permuted (x right = -y, y down =
-z, z forward = x) with KITTI's offsets, ``R_rect`` is the identity, the IMU sits
0.81 m behind, 0.32 m right of and 0.80 m below the Velodyne, unrotated.

Poses (:func:`oxts_rows`): the Velodyne world pose of each frame (ego pose plus the
mount) goes through the devkit's Mercator projection backwards, anchored at
the first IMU's true latitude / longitude on a georeferenced (OSM) map, else Karlsruhe
(49.0 N, 8.4 E); roll = pitch = 0 (the world is flat), velocities and yaw rate from
the ego's motion.

Labels (:func:`label_rows`), every agent in front of the camera whose box projects
into the 1242 x 375 image (KITTI annotates what its camera sees): ``Car`` (``Van``
above 2.0 m, ``Truck`` above 2.8 m), ``Pedestrian``, ``Cyclist``; the track id is the
agent index; ``truncated`` the share of the projected box outside the image;
``occluded`` 0 with at least 20 LIDAR returns on the agent, 1 with some, 2 with none;
the 3-D box in the rectified camera frame (bottom-face centre, ``rotation_y``) and
``alpha = rotation_y - atan2(x, z)``. Agents outside the image or beyond the LIDAR's
``max_range`` are not written, so the converter's label grid ignores the cells outside
the camera's view as on real KITTI (no ``DontCare`` rows are needed: the simulator
knows every agent in view, occluded ones included, marked ``occluded = 2``).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.kitti.poses import lat_to_scale, latlon_to_mercator, mercator_to_latlon
from dstenv.kitti.readers import Calibration
from dstenv.sim.types import AgentKind, Agents

__all__ = ["IMAGE_SIZE", "sim_calibration", "calib_text", "oxts_rows", "label_rows",
           "export_drive"]

#: Left colour image size of KITTI's tracking sequences ``(width, height)`` [px].
IMAGE_SIZE: tuple[int, int] = (1242, 375)
_K = (721.5377, 609.5593, 172.854)  # fx = fy, cx, cy of sequence 0003 [px]
_BASE = (44.85728, 0.2163791, 0.002745884)  # P2's 4th column (camera 2 offset)
_VELO_CAM_T = (-0.004069766, -0.07631618, -0.2717806)  # Velodyne origin in camera 0 [m]
_IMU_VELO_T = (-0.8086759, 0.3195559, -0.7997231)  # IMU -> Velodyne translation [m]
_KARLSRUHE = (49.0, 8.4)  # [deg] anchor of worlds without a georeference
_ALTITUDE = 114.0  # [m]


def sim_calibration() -> Calibration:
    """The simulated rig (module docstring) as a :class:`Calibration`."""
    fx, cx, cy = _K
    p2 = np.array([[fx, 0, cx, _BASE[0]], [0, fx, cy, _BASE[1]], [0, 0, 1, _BASE[2]]])
    velo_cam = np.eye(4)
    velo_cam[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    velo_cam[:3, 3] = _VELO_CAM_T
    imu_velo = np.eye(4)
    imu_velo[:3, 3] = _IMU_VELO_T
    return Calibration(P2=p2, R_rect=np.eye(4), Tr_velo_cam=velo_cam, Tr_imu_velo=imu_velo)


def calib_text(calib: Calibration) -> str:
    """``calib/SSSS.txt`` content in the tracking benchmark's layout (P0..P3 share K)."""
    def row(m: np.ndarray) -> str:
        return " ".join(f"{v:.12e}" for v in np.asarray(m).ravel())

    p0 = calib.P2.copy()
    p0[:, 3] = 0.0
    lines = [f"P0: {row(p0)}", f"P1: {row(p0)}", f"P2: {row(calib.P2)}", f"P3: {row(calib.P2)}",
             f"R_rect {row(calib.R_rect[:3, :3])}", f"Tr_velo_cam {row(calib.Tr_velo_cam[:3])}",
             f"Tr_imu_velo {row(calib.Tr_imu_velo[:3])}"]
    return "\n".join(lines) + "\n"


def oxts_rows(velo_poses: np.ndarray, speed: np.ndarray, yaw_rate: np.ndarray,
              calib: Calibration, latlon0: tuple[float, float] = _KARLSRUHE) -> np.ndarray:
    """OXTS rows whose devkit poses are the given Velodyne poses (up to a translation).

    Args:
        velo_poses: ``(N, 3)`` Velodyne world poses ``(x, y, yaw)`` [m, m, rad].
        speed: ``(N,)`` forward speed [m/s]; ``yaw_rate``: ``(N,)`` [rad/s].
        calib: gives ``Tr_imu_velo`` (IMU -> Velodyne).
        latlon0: latitude, longitude of the first frame's IMU [deg].

    Returns:
        ``(N, 30) float64`` rows in the devkit's column order.
    """
    poses = np.asarray(velo_poses, dtype=np.float64)
    n = len(poses)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    velo = np.tile(np.eye(4), (n, 1, 1))
    velo[:, 0, 0], velo[:, 0, 1], velo[:, 1, 0], velo[:, 1, 1] = c, -s, s, c
    velo[:, 0, 3], velo[:, 1, 3] = poses[:, 0], poses[:, 1]
    imu = velo @ calib.Tr_imu_velo  # the reader: velo = imu @ inv(Tr_imu_velo)
    scale = lat_to_scale(latlon0[0])
    mx0, my0 = latlon_to_mercator(np.array(latlon0[0]), np.array(latlon0[1]), scale)
    lat, lon = mercator_to_latlon(imu[:, 0, 3] - imu[0, 0, 3] + mx0,
                                  imu[:, 1, 3] - imu[0, 1, 3] + my0, scale)
    out = np.zeros((n, 30))
    out[:, 0], out[:, 1] = lat, lon
    out[:, 2] = _ALTITUDE + imu[:, 2, 3]
    out[:, 5] = poses[:, 2]  # yaw: 0 = east, counter-clockwise (devkit)
    out[:, 6], out[:, 7] = speed * s, speed * c  # vn, ve
    out[:, 8] = speed  # vf
    out[:, 19] = out[:, 22] = yaw_rate  # wz, wu
    out[:, 23:25] = 0.05  # position / velocity accuracy [m], [m/s]
    out[:, 25:30] = (4, 10, 4, 4, 4)  # navstat, numsats, posmode, velmode, orimode
    return out


def _kitti_type(kind: int, height: float) -> str:
    if kind == AgentKind.PEDESTRIAN:
        return "Pedestrian"
    if kind == AgentKind.CYCLIST:
        return "Cyclist"
    return "Truck" if height > 2.8 else "Van" if height > 2.0 else "Car"


def label_rows(frame: int, agents: Agents, velo_pose: np.ndarray, calib: Calibration,
               returns: np.ndarray, mount_height: float = 1.73,
               max_range: float = 120.0) -> list[str]:
    """``label_02`` rows of one frame (rules in the module docstring).

    Args:
        frame: frame index.
        agents: the world's agents (world frame).
        velo_pose: ``(3,)`` Velodyne world pose.
        calib: the rig.
        returns: ``(N,) int`` LIDAR returns on each agent this frame.
        mount_height: the Velodyne above the (flat) road [m].
        max_range: agents farther than this (horizontally) are not labelled [m].
    """
    if not len(agents):
        return []
    x0, y0, yaw0 = (float(v) for v in velo_pose)
    c, s = np.cos(yaw0), np.sin(yaw0)
    d = agents.xy - (x0, y0)
    lx, ly = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    lyaw = agents.yaw - yaw0
    velo_rect = calib.velo_to_rect
    proj = calib.P2 @ velo_rect
    w_img, h_img = IMAGE_SIZE
    rows = []
    for k in range(len(agents)):
        if np.hypot(lx[k], ly[k]) > max_range:
            continue
        hl, hw, h = agents.length[k] / 2, agents.width[k] / 2, agents.height[k]
        ck, sk = np.cos(lyaw[k]), np.sin(lyaw[k])
        ox = np.array([hl, hl, -hl, -hl] * 2)
        oy = np.array([hw, -hw, -hw, hw] * 2)
        z = np.repeat([0.0, h], 4)  # corner heights above the road
        ground_z = -mount_height
        corners = np.stack([lx[k] + ck * ox - sk * oy, ly[k] + sk * ox + ck * oy,
                            ground_z + z, np.ones(8)], axis=1)
        q = corners @ proj.T
        if np.any(q[:, 2] <= 0.1):
            continue  # (partly) behind the camera: not in the image
        uv = q[:, :2] / q[:, 2:]
        box = np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])
        clip = np.clip(box, 0, [w_img - 1, h_img - 1, w_img - 1, h_img - 1])
        area = (box[2] - box[0]) * (box[3] - box[1])
        inside = max(clip[2] - clip[0], 0) * max(clip[3] - clip[1], 0)
        if inside <= 0:
            continue
        truncated = 1.0 - inside / max(area, 1e-9)
        bottom = velo_rect @ np.array([lx[k], ly[k], ground_z, 1.0])
        heading = velo_rect[:3, :3] @ np.array([ck, sk, 0.0])
        ry = float(np.arctan2(-heading[2], heading[0]))  # camera heading (cos ry, 0, -sin ry)
        alpha = ry - float(np.arctan2(bottom[0], bottom[2]))
        alpha = (alpha + np.pi) % (2 * np.pi) - np.pi
        occluded = 0 if returns[k] >= 20 else 1 if returns[k] > 0 else 2
        name = _kitti_type(int(agents.kind[k]), float(h))
        rows.append(
            f"{frame} {k} {name} {truncated:.2f} {occluded} {alpha:.6f} "
            f"{clip[0]:.2f} {clip[1]:.2f} {clip[2]:.2f} {clip[3]:.2f} "
            f"{h:.6f} {agents.width[k]:.6f} {agents.length[k]:.6f} "
            f"{bottom[0]:.6f} {bottom[1]:.6f} {bottom[2]:.6f} {ry:.6f}")
    return rows


def _rot(yaw: float) -> np.ndarray:
    return np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])


def export_drive(config: Mapping[str, Any], seed: int, frames: int, out: str | Path,
                 sequence: int = 0) -> Path:
    """Simulate ``frames`` steps with the 3-D LIDAR and write them as a KITTI sequence.

    Args:
        config: full pipeline configuration (``lidar.model`` is forced to ``"hdl64"``).
        seed: episode seed.
        frames: number of frames (10 Hz).
        out: dataset folder; ``out/training/...`` is written.
        sequence: the sequence number ``SSSS``.

    Returns:
        The ``training`` folder.
    """
    from dstenv.config import merge_config
    from dstenv.pipeline import Pipeline
    from dstenv.sensing.lidar3d import SURFACES

    if frames < 1:
        raise ValueError(f"export-kitti: --frames must be >= 1, got {frames}")
    if not 0 <= int(sequence) <= 9999:
        raise ValueError(f"export-kitti: --sequence must be in 0..9999 (KITTI's SSSS), got "
                         f"{sequence}")
    split = Path(out) / "training"
    name = f"{int(sequence):04d}"
    targets = {"velodyne": split / "velodyne" / name, "oxts": split / "oxts" / f"{name}.txt",
               "calib": split / "calib" / f"{name}.txt",
               "label_02": split / "label_02" / f"{name}.txt"}
    held = [str(t.relative_to(split)) for t in targets.values() if t.exists()]
    if held:  # never over (or beside) a sequence already there, real or exported
        raise FileExistsError(f"export-kitti: {split} already holds sequence {name} "
                              f"({', '.join(held)}); pick another --sequence or --out "
                              "(nothing was written)")
    cfg = merge_config(config, {"lidar": {"model": "hdl64"}}, "config")
    pipe = Pipeline(cfg)
    # written into a staging folder, moved into place when complete: a killed export
    # leaves no half sequence (the next run clears its staging folder)
    stage = split / f".export-{name}.partial"
    if stage.exists():
        shutil.rmtree(stage)
    (stage / "velodyne").mkdir(parents=True)
    calib = sim_calibration()
    mount = np.array([cfg["lidar"]["mount_x"], cfg["lidar"]["mount_y"]])
    poses, speeds, labels = [], [], []
    for f in range(frames):
        frame = pipe.reset(seed) if f == 0 else pipe.step()
        world, cloud = pipe.world, pipe.sweep
        ego = np.asarray(frame.ego_pose, dtype=np.float64)
        c, s = np.cos(ego[2]), np.sin(ego[2])
        velo = np.array([ego[0] + c * mount[0] - s * mount[1],
                         ego[1] + s * mount[0] + c * mount[1], ego[2]])
        scan = stage / "velodyne" / f"{f:06d}.bin"
        try:  # (ndarray.tofile on a full disk said only "496944 requested and 316416 written")
            scan.write_bytes(cloud.points.astype("<f4").tobytes())
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror or str(exc), str(scan)) from None
        on_agent = cloud.surface == SURFACES.index("agent")
        returns = np.bincount(cloud.index[on_agent], minlength=len(world.agents))
        labels += label_rows(f, world.agents, velo, calib, returns,
                             float(cfg["lidar"]["hdl64"]["mount_height"]),
                             float(cfg["lidar"]["hdl64"]["max_range"]))
        poses.append(velo)
        speeds.append(float(world.ego_speed))
    poses_a = np.stack(poses)
    dyaw = np.diff(np.unwrap(poses_a[:, 2]), prepend=poses_a[0, 2])
    dt = float(cfg["world"]["dt"]) if cfg["source"] == "city" else 0.1
    meta = pipe.world.map.meta
    latlon0 = _KARLSRUHE
    if "mercator_offset" in meta:  # a georeferenced (OSM) map: the first IMU's true place
        imu0 = poses_a[0, :2] + _rot(poses_a[0, 2]) @ np.asarray(_IMU_VELO_T[:2])
        lat, lon = mercator_to_latlon(imu0[0] + meta["mercator_offset"][0],
                                      imu0[1] + meta["mercator_offset"][1],
                                      meta["mercator_scale"])
        latlon0 = (float(lat), float(lon))
    oxts = oxts_rows(poses_a, np.array(speeds), dyaw / dt, calib, latlon0)
    (stage / "oxts").write_text(
        "\n".join(" ".join(f"{v:.12g}" for v in row) for row in oxts) + "\n")
    (stage / "calib").write_text(calib_text(calib))
    (stage / "label_02").write_text("\n".join(labels) + ("\n" if labels else ""))
    for key, target in targets.items():
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(stage / key, target)
    stage.rmdir()
    return split
