"""The committed unrolled kernel is exactly what the generator writes."""

from dstenv.dst import _codegen
from dstenv.dst._kernel import REACHABLE


def test_generated_kernel_is_up_to_date():
    assert _codegen.TARGET.read_text() == _codegen.render(), (
        "dstenv/dst/_fused.py is stale: run `python -m dstenv.dst._codegen`"
    )


def test_reachable_sets():
    assert list(REACHABLE) == [1, 2, 3, 4, 8, 9, 10, 12, 15, 16, 24, 25, 26, 28, 31]
