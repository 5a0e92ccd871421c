"""Labelled data: HDF5 shards, generation, manifests and PyTorch datasets.

* :mod:`dstenv.data.shards`: the shard format (documented there), ``ShardWriter``,
  ``ShardReader``, ``ShardError``;
* :mod:`dstenv.data.manifest`: ``manifest.json`` of a dataset directory;
* :mod:`dstenv.data.sampling`: disjoint train/val/test map seeds, frame sampling;
* :mod:`dstenv.data.generate`: ``dstenv generate`` (processes or Ray); call it from
  Python as ``dstenv.data.generate.generate(spec, out)``;
* :mod:`dstenv.data.datasets`: ``ShardDataset`` and ``StreamingDataset`` (PyTorch).

Names are imported lazily so that ``import dstenv.data`` does not import torch.
"""

from __future__ import annotations

from dstenv._lazy import lazy_attributes

__all__ = [
    "ShardWriter", "ShardReader", "ShardError",
    "ManifestError", "load_manifest", "write_manifest",
    "GenerateSpec",
    "ShardDataset", "StreamingDataset",
]

_WHERE = {
    "ShardWriter": "shards", "ShardReader": "shards", "ShardError": "shards",
    "ManifestError": "manifest", "load_manifest": "manifest", "write_manifest": "manifest",
    "GenerateSpec": "generate",
    "ShardDataset": "datasets", "StreamingDataset": "datasets",
}


__getattr__, __dir__ = lazy_attributes(__name__, _WHERE)
