"""What the benchmark compares: anything that maps a batch of inputs to a class per cell.

Two kinds:

* :class:`DSTSegmenter` -- the pure-DST baseline: argmax of the pignistic
  probability BetP (input channels 0..4). Its :attr:`~DSTSegmenter.params` say
  which DST parameters produced that BetP; stored frames hold BetP computed with
  the *generation* parameters, so for any other parameters the benchmark replays
  the episode's sensor and GIS grids through a fresh filter
  (:mod:`dstenv.segment.replay`) before calling :meth:`predict`.
  :class:`DSTFreeSegmenter` (``dst-free``) also reads the current sensor grid: no
  object where the sweep saw free space (:func:`free_space_veto`).
* :class:`TorchSegmenter` -- a network from :mod:`dstenv.segment.models` reading
  the stored input as is (the paper's 10 channels: BetP at t and t-1).
  :class:`EnsembleSegmenter` averages the class scores of several such networks.
"""

from __future__ import annotations

from typing import Any

import torch

from dstenv.dst.frame import CLASSES
from dstenv.dst.params import DSTParams
from dstenv.segment.models import SegmentationModel, build_model

__all__ = ["Segmenter", "DSTSegmenter", "DSTFreeSegmenter", "TorchSegmenter",
           "EnsembleSegmenter", "free_space_veto"]

_NAV, _NONNAV = CLASSES.index("navigable"), CLASSES.index("non_navigable")
#: the first class index that is an obstacle (building, static, moving)
_FIRST_OBSTACLE = CLASSES.index("building")


class Segmenter:
    """Base class: ``predict(x (B, C, H, W) float32) -> (B, H, W) int64``.

    Attributes:
        name: the registry name (``"dst"``, ``"unet-light"``...).
        label: a human-readable name for tables (e.g. ``"dst (paper)"``).
    """

    name: str = ""
    label: str = ""

    def predict(self, x: torch.Tensor) -> torch.Tensor:  # pragma: no cover - interface
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        """JSON-compatible description for reports."""
        return {"name": self.name, "label": self.label}


class DSTSegmenter(Segmenter):
    """Argmax of BetP over :data:`dstenv.dst.CLASSES`.

    Args:
        params: DST parameters that must have produced the BetP it is given.
        name: registry name.
        label: table label; defaults to ``name``.
        info: extra JSON-compatible facts for the report (e.g. the tuning trace).
    """

    def __init__(
        self,
        params: DSTParams,
        name: str = "dst",
        label: str | None = None,
        info: dict | None = None,
    ):
        self.params = params
        self.name = name
        self.label = label or name
        self.info = dict(info or {})

    def predict(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 4 or x.shape[1] < 5:
            raise ValueError(f"DST segmenter needs (B, >=5, H, W) BetP input, got {tuple(x.shape)}")
        return x[:, :5].argmax(1)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "params": self.params.to_dict(), **self.info}


def free_space_veto(pred: torch.Tensor, betp: torch.Tensor, free: torch.Tensor) -> torch.Tensor:
    """No obstacle where the current sweep saw free space.

    A cell the sweep saw free had a beam pass through it (or hit the ground in it)
    without an echo, so no building, parked or moving object stands there now,
    whatever evidence the filter still carries from earlier sweeps (the trail a moving
    car leaves). Such cells predicted ``building``, ``static`` or ``moving`` become
    ``navigable`` or ``non_navigable``, whichever has the larger BetP.

    Args:
        pred: ``(B, H, W) int64`` predicted classes.
        betp: ``(B, >=2, H, W)`` BetP (channels in :data:`CLASSES` order).
        free: ``(B, H, W) bool`` cells seen free in the current sweep.

    Returns:
        ``(B, H, W) int64``, a new tensor.
    """
    ground = torch.where(betp[:, _NAV] >= betp[:, _NONNAV], _NAV, _NONNAV)
    return torch.where(free & (pred >= _FIRST_OBSTACLE), ground, pred)


class DSTFreeSegmenter(DSTSegmenter):
    """``dst-free``: argmax of BetP, then :func:`free_space_veto` with the current sweep.

    Reads ``fcn10+sensor`` (:func:`dstenv.data.inputs.network_input`): BetP at t and
    t-1, then the sensor grid as seen-free and seen-occupied channels (10 and 11).
    """

    inputs = "fcn10+sensor"

    def __init__(self, params: DSTParams, label: str = "dst-free",
                 info: dict | None = None) -> None:
        super().__init__(params, "dst-free", label, info)

    def predict(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 4 or x.shape[1] < 12:
            raise ValueError("dst-free needs (B, >=12, H, W) fcn10+sensor input (BetP at t "
                             f"and t-1, then the sensor grid), got {tuple(x.shape)}")
        return free_space_veto(x[:, :5].argmax(1), x[:, :5], x[:, 10] > 0.5)


class _ScoringSegmenter(Segmenter):
    """A segmenter with class scores (:meth:`logits`) and a decision rule on them
    (:attr:`decision`, :mod:`dstenv.segment.decide`; ``None``: argmax)."""

    decision: dict[str, Any] | None = None

    def logits(self, x: torch.Tensor) -> torch.Tensor:  # pragma: no cover - interface
        raise NotImplementedError

    def predict(self, x: torch.Tensor) -> torch.Tensor:
        from dstenv.segment.decide import apply_decision  # argmax when decision is None

        return apply_decision(self.logits(x), x, self.decision)

    def _with_decision(self, out: dict[str, Any]) -> dict[str, Any]:
        """``out`` (a :meth:`describe`) with the decision, without its confusion table."""
        if self.decision is not None:
            out["decision"] = {k: v for k, v in self.decision.items() if k != "confusion"}
        return out


class TorchSegmenter(_ScoringSegmenter):
    """A network created by :func:`dstenv.segment.models.build_model`.

    ``trained_cell_size`` [m]: the cells of its training data when its checkpoint says
    (:func:`dstenv.segment.checkpoint.load_segmenter`), else ``None``.

    Args:
        model_name: key of :data:`dstenv.segment.models.MODELS`.
        model_kwargs: builder options (JSON-compatible, stored in checkpoints).
        in_channels, num_classes: network input channels and classes.
        device: where :meth:`predict` runs.
        inputs: what the input channels are, a key of
            :data:`dstenv.data.datasets.INPUTS` (``"fcn10"``: BetP at t and t-1).
    """

    def __init__(
        self,
        model_name: str,
        model_kwargs: dict[str, Any] | None = None,
        in_channels: int = 10,
        num_classes: int = 5,
        device: str | torch.device = "cpu",
        inputs: str = "fcn10",
    ) -> None:
        self.name = model_name
        self.inputs = inputs
        self.label = model_name
        self.model_kwargs = dict(model_kwargs or {})
        self.in_channels = in_channels
        self.num_classes = num_classes
        self.device = torch.device(device)
        self.trained_cell_size: float | None = None
        #: decision rule on the class scores (:mod:`dstenv.segment.decide`); None: argmax
        self.decision: dict[str, Any] | None = None
        self.model: SegmentationModel = build_model(
            model_name, in_channels, num_classes, **self.model_kwargs
        )
        # NHWC: oneDNN's convolutions run 25-40 % faster on the CPU (train step and
        # forward); the state dict keeps the same values and loads into either layout
        self.model.to(device=self.device, memory_format=torch.channels_last)

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        """Class scores ``(B, num_classes, H, W)`` on the CPU (eval mode, no gradients)."""
        if x.dim() != 4 or x.shape[1] != self.in_channels:
            raise ValueError(
                f"{self.name} needs (B, {self.in_channels}, H, W) input, got {tuple(x.shape)}"
            )
        was_training = self.model.training
        self.model.eval()
        try:
            with torch.no_grad():
                return self.model(x.to(self.device)).cpu()
        finally:
            self.model.train(was_training)

    def spec(self) -> dict[str, Any]:
        """JSON-compatible recipe to rebuild the network (stored in checkpoints)."""
        return {
            "model": self.name,
            "model_kwargs": self.model_kwargs,
            "in_channels": self.in_channels,
            "num_classes": self.num_classes,
            "inputs": self.inputs,
        }

    def describe(self) -> dict[str, Any]:
        n = sum(p.numel() for p in self.model.parameters())
        return self._with_decision({**super().describe(), **self.spec(), "parameters": n})


class EnsembleSegmenter(_ScoringSegmenter):
    """The mean of the class scores (logits) of ``members``, networks reading the same
    input; :attr:`decision` as :class:`TorchSegmenter`'s (``None``: argmax).

    Raises:
        ValueError: fewer than two members, members that read different inputs or give
            different classes, or members trained on different cell sizes (each named
            by its label).
    """

    def __init__(self, members: list[TorchSegmenter], label: str | None = None) -> None:
        if len(members) < 2:
            raise ValueError(f"an ensemble needs at least two networks, got {len(members)}")
        first = members[0]
        for m in members[1:]:
            if (m.inputs, m.in_channels, m.num_classes) != (first.inputs, first.in_channels,
                                                            first.num_classes):
                raise ValueError(f"ensemble members differ: {m.label} reads {m.inputs!r} "
                                 f"({m.in_channels} channels, {m.num_classes} classes), "
                                 f"{first.label} {first.inputs!r} ({first.in_channels}, "
                                 f"{first.num_classes}); use networks that read the same input")
        cells = {m.trained_cell_size for m in members} - {None}
        if len(cells) > 1:
            raise ValueError("ensemble members were trained on different cells ("
                             + ", ".join(f"{m.label}: {m.trained_cell_size} m" for m in members)
                             + "); use networks trained at one cell size")
        self.members = list(members)
        names = list(dict.fromkeys(m.name for m in members))
        self.name = f"ensemble-{'+'.join(names)}"
        self.label = label or f"{'+'.join(names)} ensemble of {len(members)}"
        self.inputs, self.in_channels = first.inputs, first.in_channels
        self.num_classes = first.num_classes
        self.trained_cell_size: float | None = cells.pop() if cells else None
        self.decision: dict[str, Any] | None = None
        #: where the members came from (``[{"source", "sha256"}]``), when loaded from a file
        self.sources: list[dict[str, Any]] | None = None

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        """Mean class scores of the members, ``(B, num_classes, H, W)``."""
        return torch.stack([m.logits(x) for m in self.members]).mean(0)

    def describe(self) -> dict[str, Any]:
        return self._with_decision({
            **super().describe(), "inputs": self.inputs, "in_channels": self.in_channels,
            "num_classes": self.num_classes,
            "parameters": sum(p.numel() for m in self.members for p in m.model.parameters()),
            "members": self.sources or [m.label for m in self.members]})
