"""Shared model tester: every registered network, forward/backward at two sizes, save/load."""

import pytest
import torch

from dstenv.segment.checkpoint import load_segmenter, save_checkpoint
from dstenv.segment.models import MODELS, build_model, count_parameters
from dstenv.segment.models.fcn8s import bilinear_kernel, load_vgg16_weights
from dstenv.segment.registry import SEGMENTERS, create_segmenter

# small options keep the tests fast; the full FCN-8s is covered by the slow test
FAST_KWARGS = {"fcn8s-vgg16": {"fc_channels": 32}}
SIZES = {"fcn8s-vgg16": [(32, 32), (40, 64)]}


@pytest.mark.parametrize("name", sorted(MODELS))
class TestModel:
    def make(self, name):
        torch.manual_seed(0)
        return build_model(name, in_channels=10, num_classes=5, **FAST_KWARGS.get(name, {}))

    def test_forward_backward_two_resolutions(self, name):
        model = self.make(name)
        for h, w in SIZES.get(name, [(64, 64), (96, 128)]):
            x = torch.rand(2, 10, h, w)
            logits = model(x)
            assert logits.shape == (2, 5, h, w)
            loss = torch.nn.functional.cross_entropy(logits, torch.randint(0, 5, (2, h, w)))
            model.zero_grad()
            loss.backward()
            grads = [p.grad for p in model.parameters() if p.requires_grad]
            assert all(g is not None for g in grads)
            assert sum(float(g.abs().sum()) for g in grads) > 0

    def test_odd_size_is_padded_and_cropped(self, name):
        model = self.make(name).eval()
        x = torch.rand(1, 10, 37, 45)
        assert model(x).shape == (1, 5, 37, 45)
        pred = model.predict(x)
        assert pred.shape == (1, 37, 45) and pred.dtype == torch.int64

    def test_save_load_round_trip(self, name, tmp_path):
        seg = create_segmenter(name, **FAST_KWARGS.get(name, {}))
        seg.model.eval()
        path = save_checkpoint(
            tmp_path / "m.pt", {"spec": seg.spec(), "model": seg.model.state_dict()}
        )
        again = load_segmenter(path)
        x = torch.rand(2, 10, 32, 32)
        with torch.no_grad():
            assert torch.equal(seg.model(x), again.model(x))
        assert torch.equal(seg.predict(x), again.predict(x))


def test_registry_covers_all_models():
    learned = {n for n, e in SEGMENTERS.items() if e.kind == "learned"}
    assert learned == set(MODELS)
    assert SEGMENTERS["dst"].kind == SEGMENTERS["dst-tuned"].kind == "dst"


def test_light_models_are_light():
    for name in ("unet-light", "unet-temporal"):
        assert 200_000 <= count_parameters(build_model(name)) <= 1_000_000


def test_temporal_streams_are_separate():
    # changing only the t-1 half must not touch the t stream's output
    model = build_model("unet-temporal").eval()
    x = torch.rand(1, 10, 16, 16)
    y = x.clone()
    y[:, 5:] = torch.rand(1, 5, 16, 16)
    enc = model.encoder
    with torch.no_grad():
        assert torch.equal(enc.stream_t(x[:, :5]), enc.stream_t(y[:, :5]))
        assert not torch.equal(model(x), model(y))


def test_bilinear_kernel_upsamples_constant():
    up = torch.nn.ConvTranspose2d(2, 2, 4, stride=2, padding=1, bias=False)
    with torch.no_grad():
        up.weight.copy_(bilinear_kernel(2, 4))
    out = up(torch.ones(1, 2, 6, 6))
    assert torch.allclose(out[..., 1:-1, 1:-1], torch.ones(1, 2, 10, 10))


def test_vgg16_weights_from_local_file(tmp_path):
    # a torchvision-layout state dict (fc layers flattened like nn.Linear)
    model = build_model("fcn8s-vgg16", fc_channels=16)
    enc = model.encoder
    sd = {f"features.{k}": torch.full_like(v, 0.5) for k, v in enc.features.state_dict().items()}
    sd["classifier.0.weight"] = torch.arange(16 * 512 * 49, dtype=torch.float32).reshape(
        16, 512 * 49
    )
    sd["classifier.0.bias"] = torch.zeros(16)
    sd["classifier.3.weight"] = torch.ones(16, 16)
    sd["classifier.3.bias"] = torch.zeros(16)
    torch.save(sd, tmp_path / "vgg16.pth")
    load_vgg16_weights(enc, tmp_path / "vgg16.pth")
    assert float(enc.features[0].weight.detach().mean()) == 0.5
    assert float(enc.fc6.weight.detach()[0, 0, 0, 1]) == 1.0 and enc.fc6.weight.shape == (
        16,
        512,
        7,
        7,
    )
    del sd["classifier.3.bias"]
    torch.save(sd, tmp_path / "bad.pth")
    with pytest.raises(ValueError, match="missing key"):
        load_vgg16_weights(enc, tmp_path / "bad.pth")
    with pytest.raises(FileNotFoundError):
        build_model("fcn8s-vgg16", fc_channels=16, vgg16_weights=str(tmp_path / "none.pth"))
    (tmp_path / "text.pth").write_text("not weights\n")  # a traceback before
    with pytest.raises(ValueError, match="text.pth: not a saved torch state dict"):
        load_vgg16_weights(enc, tmp_path / "text.pth")
    torch.save([1, 2], tmp_path / "list.pth")
    with pytest.raises(ValueError, match="holds a list, not a state dict"):
        load_vgg16_weights(enc, tmp_path / "list.pth")


@pytest.mark.slow
def test_full_fcn8s_forward_backward():
    model = build_model("fcn8s-vgg16")
    assert count_parameters(model) > 130_000_000
    x = torch.rand(1, 10, 64, 64)
    logits = model(x)
    assert logits.shape == (1, 5, 64, 64)
    logits.sum().backward()


def test_betp_skip_starts_from_dst_and_learns_its_weight():
    """With the head zeroed, a betp_skip model predicts DST's argmax of BetP at t; the
    skip weight is a trained parameter; without the option the parameters are as before."""
    torch.manual_seed(0)
    plain = build_model("unet-light", base=8, depth=2)
    model = build_model("unet-light", base=8, depth=2, betp_skip=1.0)
    assert set(model.state_dict()) - set(plain.state_dict()) == {"betp_weight"}
    head = model.head[-1]
    torch.nn.init.zeros_(head.weight)
    torch.nn.init.zeros_(head.bias)
    betp = torch.rand(2, 5, 21, 19)
    betp = betp / betp.sum(1, keepdim=True)
    x = torch.cat([betp, torch.rand(2, 5, 21, 19)], 1)
    assert torch.equal(model.predict(x), betp.argmax(1))  # odd size: padded, cropped
    loss = model(x).logsumexp(1).mean()
    loss.backward()
    assert model.betp_weight.grad is not None and model.betp_weight.grad != 0
    with pytest.raises(ValueError, match="betp_skip must be >= 0"):
        build_model("unet-light", betp_skip=-1.0)


@pytest.mark.parametrize("kwargs, message", [
    ({"depth": 40}, "depth: an integer in 1..8"),  # ran a 24 GB machine out of memory
    ({"base": 0}, "base: an integer in 1..256"),
    ({"base": -4}, "base: an integer in 1..256"),
    ({"base": 4.5}, "base: an integer in 1..256"),
    ({"base": 256, "depth": 8}, "at most 4096"),
])
def test_unet_sizes_are_checked_before_any_allocation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        build_model("unet-light", 10, 5, **kwargs)
