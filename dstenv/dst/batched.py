"""The perception-grid update for B grids at once, in torch (CPU or GPU).

:class:`BatchedGridFilter` runs ``dst-spec.md`` steps 1-8 for a batch of independent
grids (one per simulated stream) as a handful of tensor operations, so a GPU fuses
many streams per call while CPU workers simulate. It agrees with
:class:`~dstenv.dst.PerceptionGridFilter` (the numba kernel) to float32 rounding
(tests: < 1e-5 on every mass, BetP and zeta over many steps with ego motion).

How it is laid out (the same facts the numba kernel is generated from,
:mod:`dstenv.dst._codegen`):

* state: only the 15 :data:`~dstenv.dst._codegen.REACHABLE` subsets can carry mass,
  so masses are ``(B, 15, H*W)``;
* step 1, the ego-motion warp: the source cell of every cell by the float64 formula
  of :func:`dstenv.dst.reference.source_cells` (the same operations in the same
  order, hence the same cells), then one ``gather``; cells from outside are vacuous;
* step 2: ``m_sm = dempster(sensor, map)`` depends on the two codes only, so its 12
  possible vectors are computed once by :func:`dstenv.dst.rules.dempster` and looked
  up per cell;
* step 7: the modified conjunctive rule is linear in the past masses for each
  focal set C of ``m_sm``: ``o = sum_C m_sm(C) * (R_C @ p)`` with 0/1 routing
  matrices ``R_C`` (9 small matmuls per update).

Importing this module imports torch; :mod:`dstenv.dst` itself does not.
"""

from __future__ import annotations

import numpy as np
import torch

from dstenv.dst._codegen import REACHABLE, SM_SETS, route
from dstenv.dst.frame import CLASSES, FREE, M, NUM_CLASSES, NUM_SETS, OCCUPIED, OMEGA
from dstenv.dst.inputs import MAP_SETS, SENSOR_SETS, map_masses, sensor_masses
from dstenv.dst.params import DSTParams
from dstenv.dst.rules import dempster

__all__ = ["BatchedGridFilter"]

_NR = len(REACHABLE)
_POS = {a: k for k, a in enumerate(REACHABLE)}
_N_SENSOR, _N_MAP = len(SENSOR_SETS), len(MAP_SETS)


def _tables(params: DSTParams) -> dict[str, np.ndarray]:
    """Constant matrices of the update (float32 unless noted)."""
    # m_sm for every (sensor code, map code): row s * n_map + g, columns SM_SETS
    s, g = np.meshgrid(np.arange(_N_SENSOR), np.arange(_N_MAP), indexing="ij")
    m_sm = dempster(sensor_masses(s.astype(np.uint8), params.sensor_confidence),
                    map_masses(g.astype(np.uint8), params.map_confidence))
    sm = np.stack([m_sm[c].reshape(-1) for c in SM_SETS], axis=1).astype(np.float32)
    route_m = np.zeros((len(SM_SETS), _NR, _NR), np.float32)  # [C, out d, in b]
    for ci, c in enumerate(SM_SETS):
        for b in REACHABLE:
            route_m[ci, _POS[route(b, c)], _POS[b]] = 1.0
    within = lambda sets, sub: np.array([float(a & ~sub == 0) for a in sets], np.float32)  # noqa: E731
    card = np.array([bin(a).count("1") for a in REACHABLE], np.float32)
    betp = np.array([[float(a >> x & 1) / card[k] for k, a in enumerate(REACHABLE)]
                     for x in range(NUM_CLASSES)], np.float32)
    spec_from = [k for k, a in enumerate(REACHABLE) if a & M and a != M]
    return {
        "sm": sm, "route": route_m, "betp": betp,
        "free_p": within(REACHABLE, FREE), "occ_p": within(REACHABLE, OCCUPIED),
        "free_sm": within(SM_SETS, FREE), "occ_sm": within(SM_SETS, OCCUPIED),
        "spec_from": np.array(spec_from, np.int64),
        "spec_to": np.array([_POS[REACHABLE[k] & ~M] for k in spec_from], np.int64),
    }


class BatchedGridFilter:
    """B independent perception-grid filters updated together (torch).

    Args:
        batch: number of grids B.
        shape: ``(H, W)`` of every grid (axes as in :mod:`dstenv.grid`).
        params: the update's numbers (default :meth:`DSTParams.default`).
        cell_size: cell edge [m], used to apply the ego motion.
        device: torch device (``"cpu"``, ``"cuda"``...).

    Attributes:
        masses: ``(B, 32, H, W) float32`` current grids (a new tensor each call).
        zeta: ``(B, H, W) float32`` accumulators.

    Example:
        >>> f = BatchedGridFilter(8, (256, 256), device="cuda")
        >>> betp = f.update(sensor, gis, motion)   # (8, 256, 256) uint8 x2, (8, 3)
        >>> betp.shape
        torch.Size([8, 5, 256, 256])
    """

    def __init__(self, batch: int, shape: tuple[int, int], params: DSTParams | None = None,
                 cell_size: float = 0.33, device: str | torch.device = "cpu") -> None:
        h, w = (int(v) for v in shape)
        if batch < 1 or h < 1 or w < 1:
            raise ValueError(f"batch and grid shape must be positive, got {batch}, {shape}")
        if not cell_size > 0:
            raise ValueError(f"cell_size must be > 0 m, got {cell_size}")
        self.batch, self.shape, self.cell_size = int(batch), (h, w), float(cell_size)
        self.params = params if params is not None else DSTParams.default()
        try:
            self.device = torch.device(device)
            torch.zeros(1, device=self.device)  # a device this torch build can use
        except (RuntimeError, AssertionError) as exc:
            raise ValueError(f"device {device!r}: not usable here ({str(exc).splitlines()[0]});"
                             " use 'cpu' or an available 'cuda'") from None
        t = _tables(self.params)
        dev = self.device
        self._t = {k: torch.as_tensor(v, device=dev) for k, v in t.items()}
        p = self.params
        # scalars as float32 tensors: the arithmetic stays float32 like the kernel
        self._alpha = torch.tensor(p.alpha, dtype=torch.float32, device=dev)
        self._keep = torch.tensor(1.0 - p.alpha, dtype=torch.float32, device=dev)
        i0, j0 = h // 2, w // 2
        self._x = ((i0 - torch.arange(h, dtype=torch.float64, device=dev)) * cell_size)[:, None]
        self._y = ((j0 - torch.arange(w, dtype=torch.float64, device=dev)) * cell_size)[None, :]
        self._m = torch.zeros((self.batch, _NR, h * w), dtype=torch.float32, device=dev)
        self._z = torch.zeros((self.batch, h * w), dtype=torch.float32, device=dev)
        self.reset()

    def reset(self, which: torch.Tensor | np.ndarray | None = None) -> None:
        """Total ignorance (m(Omega) = 1, zeta = 0) for all grids or the ``(B,) bool`` ones."""
        if which is None:
            which = torch.ones(self.batch, dtype=torch.bool, device=self.device)
        which = torch.as_tensor(which, device=self.device)
        if which.dtype != torch.bool or tuple(which.shape) != (self.batch,):
            raise ValueError(f"reset: which must be a ({self.batch},) bool mask, got "
                             f"{which.dtype} {tuple(which.shape)}")
        self._m[which] = 0.0
        self._m[which, _POS[OMEGA]] = 1.0
        self._z[which] = 0.0

    @property
    def masses(self) -> torch.Tensor:
        h, w = self.shape
        out = torch.zeros((self.batch, NUM_SETS, h * w), dtype=torch.float32,
                          device=self.device)
        out[:, torch.as_tensor(REACHABLE, device=self.device)] = self._m
        return out.view(self.batch, NUM_SETS, h, w)

    @property
    def zeta(self) -> torch.Tensor:
        return self._z.view(self.batch, *self.shape)

    def _warp(self, motion: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Step 1: ``(masses, zeta)`` of the previous grids moved into the current frames."""
        h, w = self.shape
        motion = motion.to(torch.float64)
        dx, dy = motion[:, 0, None, None], motion[:, 1, None, None]
        # cos/sin by numpy, as reference.source_cells and the kernel
        yaw = motion[:, 2].cpu().numpy()
        ct = torch.as_tensor(np.cos(yaw), device=self.device)[:, None, None]
        st = torch.as_tensor(np.sin(yaw), device=self.device)[:, None, None]
        inv = 1.0 / self.cell_size
        x, y = self._x, self._y
        si = torch.floor(h // 2 - (ct * x - st * y + dx) * inv + 0.5)
        sj = torch.floor(w // 2 - (st * x + ct * y + dy) * inv + 0.5)
        valid = ((si >= 0) & (si < h) & (sj >= 0) & (sj < w)).view(self.batch, -1)
        src = (si.clamp(0, h - 1) * w + sj.clamp(0, w - 1)).to(torch.int64).view(self.batch, -1)
        m = torch.gather(self._m, 2, src[:, None, :].expand(-1, _NR, -1))
        z = torch.gather(self._z, 1, src)
        m = torch.where(valid[:, None, :], m, 0.0)
        m[:, _POS[OMEGA]] = torch.where(valid, m[:, _POS[OMEGA]], 1.0)
        return m, torch.where(valid, z, 0.0)

    def update(self, sensor_states: torch.Tensor | np.ndarray, map_classes: torch.Tensor |
               np.ndarray, ego_motion: torch.Tensor | np.ndarray | None = None) -> torch.Tensor:
        """Fuse one sweep and map cut into each grid; returns BetP ``(B, 5, H, W) float32``.

        Args:
            sensor_states: ``(B, H, W)`` uint8 codes 0 unknown, 1 free, 2 occupied.
            map_classes: ``(B, H, W)`` uint8 codes 0 none, 1 building, 2 road, 3 intermediate.
            ego_motion: ``(B, 3)`` ``(dx [m], dy [m], dyaw [rad])`` per grid
                (:func:`dstenv.grid.relative_pose`), or ``None``: no grid moved.
        """
        b, (h, w), dev = self.batch, self.shape, self.device
        codes = []
        for name, given, top in (("sensor_states", sensor_states, _N_SENSOR - 1),
                                 ("map_classes", map_classes, _N_MAP - 1)):
            a = torch.as_tensor(given, device=dev)
            if a.is_floating_point() or a.is_complex():  # 0.7 was truncated to a code
                raise ValueError(f"{name} must hold integer codes, got {a.dtype}")
            if tuple(a.shape) != (b, h, w):
                raise ValueError(f"{name} must have shape {(b, h, w)}, got {tuple(a.shape)}")
            if int(a.min()) < 0 or int(a.max()) > top:
                raise ValueError(f"{name} holds codes outside 0..{top}")
            codes.append(a.to(torch.int64).contiguous())  # (a strided one failed in view)
        sensor, gis = codes
        if ego_motion is None:
            p, z = self._m, self._z
        else:
            motion = torch.as_tensor(np.asarray(ego_motion, np.float64) if not
                                     torch.is_tensor(ego_motion) else ego_motion, device=dev)
            if tuple(motion.shape) != (b, 3):
                raise ValueError(f"ego_motion must have shape {(b, 3)}, got {tuple(motion.shape)}")
            if not bool(torch.isfinite(motion).all()):  # NaN indexed out of bounds
                raise ValueError("ego_motion must be finite")
            moved = (motion != 0).any(dim=1)
            p, z = self._warp(motion)
            p = torch.where(moved[:, None, None], p, self._m)
            z = torch.where(moved[:, None], z, self._z)
        t, prm = self._t, self.params
        wsm = t["sm"][(sensor * _N_MAP + gis).view(b, -1)].transpose(1, 2)  # (B, 9, HW)
        # 3. conflicts, 4. accumulator
        mf = torch.einsum("k,bkn->bn", t["free_p"], p)
        mo = torch.einsum("k,bkn->bn", t["occ_p"], p)
        conflict = (mf * torch.einsum("c,bcn->bn", t["occ_sm"], wsm)
                    + mo * torch.einsum("c,bcn->bn", t["free_sm"], wsm))
        z_dec = torch.clamp(z - prm.delta_dec, min=0.0)
        z_inc = torch.clamp(z + prm.delta_inc, max=1.0)
        z = torch.where(conflict > prm.gamma_conflict, z_dec,
                        torch.where(mo >= prm.gamma_occupied, z_inc, z))
        # 5. specialisation, 6. discounting
        p = p.clone()
        moved_mass = z[:, None, :] * p[:, t["spec_from"]]
        p[:, t["spec_to"]] += moved_mass
        p[:, t["spec_from"]] -= moved_mass
        p = p * self._keep
        p[:, _POS[OMEGA]] += self._alpha
        # 7. modified conjunctive combination: sum over C of m_sm(C) * (R_C @ p)
        o = torch.zeros_like(p)
        for c in range(len(SM_SETS)):  # (15, 15) @ (B, 15, HW) per focal set C
            o += wsm[:, c, None, :] * torch.matmul(t["route"][c], p)
        self._m, self._z = o, z.contiguous()
        return torch.einsum("xk,bkn->bxn", t["betp"], self._m).view(b, len(CLASSES), h, w)
