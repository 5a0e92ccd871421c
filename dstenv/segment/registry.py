"""Segmenters created by name: ``create_segmenter("dst", preset="paper")``.

:data:`SEGMENTERS` is a plain dict others can extend with
:func:`register_segmenter`. Each entry has a ``kind``:

* ``"dst"`` -- a :class:`~dstenv.segment.segmenters.DSTSegmenter` (no training);
* ``"learned"`` -- a :class:`~dstenv.segment.segmenters.TorchSegmenter` (an
  untrained network; :func:`dstenv.segment.train.train` fits it).

=================  =======  ==========================================================
name               kind     what
=================  =======  ==========================================================
``dst``            dst      argmax BetP; ``preset="default"|"paper"`` or ``params=``
``dst-tuned``      dst      DST parameters searched on training episodes for mIoU
``dst-complete``   dst      DST + kerb-aligned vehicle boxes (:mod:`.complete`)
``dst-free``       dst      DST, no obstacle where the current sweep saw free space
``unet-light``     learned  small U-Net (~0.48 M parameters), CPU-trainable
``unet-temporal``  learned  U-Net with separate t and t-1 streams (paper's future work)
``fcn8s-vgg16``    learned  the paper's FCN-8s (VGG-16 body, 10 -> 3 input conv)
=================  =======  ==========================================================
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from dstenv.dst.params import DSTParams
from dstenv.registry import Registry
from dstenv.segment.models import MODELS
from dstenv.segment.segmenters import (DSTFreeSegmenter, DSTSegmenter, Segmenter,
                                       TorchSegmenter)

__all__ = [
    "SegmenterEntry",
    "SEGMENTERS",
    "register_segmenter",
    "create_segmenter",
    "segmenter_kind",
]


@dataclass(frozen=True)
class SegmenterEntry:
    """A registry entry: ``factory(**kwargs) -> Segmenter``, its kind and a description."""

    factory: Callable[..., Segmenter]
    kind: str
    description: str


def _params(params: DSTParams | dict | None) -> DSTParams:
    """``params`` as :class:`DSTParams` (a dict of fields is converted); ``None``: the
    default parameters."""
    if params is None:
        return DSTParams.default()
    return params if isinstance(params, DSTParams) else DSTParams.from_dict(params)


def _make_dst(preset: str = "default", params: DSTParams | dict | None = None) -> DSTSegmenter:
    if params is not None:
        return DSTSegmenter(_params(params), "dst", "dst (custom)")
    return DSTSegmenter(DSTParams.preset(preset), "dst", f"dst ({preset})")


def _make_dst_tuned(
    params: DSTParams | dict | None = None, episodes: Sequence[Any] | None = None, **search: Any
) -> DSTSegmenter:
    if params is not None:
        return DSTSegmenter(_params(params), "dst-tuned", "dst-tuned")
    if not episodes:
        raise ValueError(
            "dst-tuned needs training episodes to tune on (episodes=...) or fixed params="
        )
    from dstenv.segment.tune import tune_dst_params

    best, trace = tune_dst_params(episodes, **search)
    return DSTSegmenter(best, "dst-tuned", "dst-tuned", info={"tuning": trace})


def _make_dst_complete(
    params: DSTParams | dict | None = None, cell_size: float = 0.33,
    completion: dict | None = None,
) -> DSTSegmenter:
    from dstenv.segment.complete import DSTCompleteSegmenter

    return DSTCompleteSegmenter(_params(params), cell_size, completion)


def _make_dst_free(params: DSTParams | dict | None = None) -> DSTFreeSegmenter:
    return DSTFreeSegmenter(_params(params))


def _learned(model_name: str) -> Callable[..., TorchSegmenter]:
    def factory(
        in_channels: int = 10, num_classes: int = 5, device: str = "cpu", **model_kwargs: Any
    ):
        for key, value in (("in_channels", in_channels), ("num_classes", num_classes)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"segmenter {model_name!r}: {key} must be an integer >= 1, "
                                 f"got {value!r}")
        from dstenv.segment.train import resolve_device

        device = resolve_device(str(device))  # one line for cuda without a GPU
        return TorchSegmenter(model_name, model_kwargs, in_channels, num_classes, device)

    return factory


def _describe(builder: Callable[..., Any]) -> str:
    return (builder.__doc__ or "").strip().splitlines()[0] if builder.__doc__ else ""


#: name -> :class:`SegmenterEntry`: the DST segmenters, then one learned segmenter per
#: network of :data:`dstenv.segment.models.MODELS`
SEGMENTERS: Registry[SegmenterEntry] = Registry("segmenter", "", {
    "dst": SegmenterEntry(_make_dst, "dst", "argmax of the pignistic probability (pure DST)"),
    "dst-tuned": SegmenterEntry(
        _make_dst_tuned, "dst", "DST parameters tuned on the training split"
    ),
    "dst-complete": SegmenterEntry(
        _make_dst_complete, "dst", "DST plus kerb-aligned car-sized boxes (geometric completion)"
    ),
    "dst-free": SegmenterEntry(
        _make_dst_free, "dst", "DST with no obstacle where the current sweep saw free space"
    ),
    **{name: SegmenterEntry(_learned(name), "learned", _describe(builder))
       for name, builder in MODELS.items()},
})


def register_segmenter(
    name: str,
    factory: Callable[..., Segmenter],
    kind: str,
    description: str = "",
    overwrite: bool = False,
) -> None:
    """Add a segmenter to :data:`SEGMENTERS`.

    Raises:
        ValueError: if ``name`` exists (and not ``overwrite``) or ``kind`` is unknown.
    """
    if kind not in ("dst", "learned"):
        raise ValueError(f"segmenter kind must be 'dst' or 'learned', got {kind!r}")
    SEGMENTERS.register(name, SegmenterEntry(factory, kind, description), overwrite)


def segmenter_kind(name: str) -> str:
    """``"dst"`` or ``"learned"`` for a registered name."""
    return _entry(name).kind


def _entry(name: str) -> SegmenterEntry:
    return SEGMENTERS.get(name)


def create_segmenter(name: str, **kwargs: Any) -> Segmenter:
    """Create a registered segmenter; ``kwargs`` go to its factory.

    Raises:
        ValueError: an option the factory does not take (named with the ones it does),
            or a bad ``in_channels`` / ``num_classes`` / ``device`` of a network.
    """
    import inspect

    factory = _entry(name).factory
    sig = inspect.signature(factory)
    if not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        unknown = sorted(set(kwargs) - set(sig.parameters))
        if unknown:
            raise ValueError(f"segmenter {name!r}: unknown option {unknown[0]!r}; it takes "
                             + (", ".join(sig.parameters) or "none"))
    return factory(**kwargs)
