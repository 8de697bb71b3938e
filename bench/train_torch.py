#!/usr/bin/env python3
"""PyTorch reference for lightfarm's training-speed benchmark.

This is an op-for-op mirror of the Burn networks and training step in ``crates/nets``
(``unet.rs``, ``relight.rs``, ``lightmap.rs``, ``loss.rs``) and of one iteration of
``services/trainer/src/train.rs``. It MUST be kept in step with those files: when a layer,
activation, loss term, light-map lookup or optimiser setting changes there, change it here too,
or the timings (and the parameter count printed for cross-checking) stop being comparable.

One timed iteration:
  generator forward (f_N, f_A, light maps, f_S, f_R) -> generator loss (masked L1 terms,
  residual L1, least-squares adversarial term through the PatchGAN) -> backward -> Adam step;
  then critic loss on (target relit, generated relit detached) -> backward -> critic Adam step.
Like the trainer, both loss values are read back to the host (``.item()``) each step.

Adam is Burn 0.22's default (``AdamConfig::new()``): betas 0.9/0.999, epsilon 1e-5, no weight
decay; Burn's bias-corrected form m*sqrt(1-b2^t)/(1-b1^t) / (sqrt(v) + eps*sqrt(1-b2^t)) is
algebraically torch's m_hat / (sqrt(v_hat) + eps). Learning rate 1e-4.

Inputs are fixed random tensors (seeded) of the trainer's shapes; data loading is not timed.
On CUDA, TF32 is disabled unless ``--tf32`` is given, so both sides compute in plain f32.

Usage:
  python bench/train_torch.py --batch 2 --size 256 --widths 32,64,128,256,512 \
      --gan-width 32 --render-net decomposed --warmup 1 --iters 3 --threads 2 [--device cuda]

Prints one JSON line on stdout; human-readable notes (parameter counts) go to stderr.
"""

import argparse
import json
import math
import statistics
import sys
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

LEAK = 0.2  # unet.rs / loss.rs leaky_relu slope
PHONG_EXPONENTS = [1, 16, 32, 64, 1024]  # light/src/lightmaps.rs
LENS_MAP = 4  # index of the exponent-1024 map, looked up with the lens normal
# Prefiltered map (height, width) per exponent: default_resolution() output width w, height w/2.
PHONG_SIZES = [(16, 32), (32, 64), (32, 64), (32, 64), (128, 256)]


def burn_conv(cin, cout, k, stride=1, padding=0):
    """Conv2d with Burn's default init: KaimingUniform(gain 1/sqrt(3)) on weight and bias,
    i.e. U(-1/sqrt(fan_in), 1/sqrt(fan_in)) for both (the same bound as torch's default)."""
    conv = nn.Conv2d(cin, cout, k, stride=stride, padding=padding, bias=True)
    bound = 1.0 / math.sqrt(cin * k * k)
    with torch.no_grad():
        conv.weight.uniform_(-bound, bound)
        conv.bias.uniform_(-bound, bound)
    return conv


class ConvBlock(nn.Module):
    """Two 3x3 'same' convolutions, each followed by leaky_relu(0.2)."""

    def __init__(self, cin, cout):
        super().__init__()
        self.first = burn_conv(cin, cout, 3, padding=1)
        self.second = burn_conv(cout, cout, 3, padding=1)

    def forward(self, x):
        x = F.leaky_relu(self.first(x), LEAK)
        return F.leaky_relu(self.second(x), LEAK)


class UNet(nn.Module):
    """unet.rs: avg-pool down, nearest up to the skip's size, cat [up, skip], 1x1 head."""

    def __init__(self, cin, cout, widths):
        super().__init__()
        w = widths
        self.down = nn.ModuleList(
            ConvBlock(cin if level == 0 else w[level - 1], width) for level, width in enumerate(w)
        )
        self.up = nn.ModuleList(ConvBlock(w[level + 1] + w[level], w[level]) for level in range(len(w) - 1))
        self.head = burn_conv(w[0], cout, 1)

    def forward(self, x):
        skips = []
        for level, block in enumerate(self.down):
            if level > 0:
                x = F.avg_pool2d(x, 2, stride=2)
            x = block(x)
            skips.append(x)
        skips.pop()
        for block in reversed(self.up):
            skip = skips.pop()
            up = F.interpolate(x, size=skip.shape[-2:], mode="nearest")
            x = block(torch.cat([up, skip], 1))
        return self.head(x)


def unit(v):
    """relight.rs unit(): v / sqrt(sum(v^2, dim 1) + 1e-8)."""
    return v / (v.pow(2).sum(1, keepdim=True) + 1e-8).sqrt()


class LightBatch:
    """lightmap.rs LightBatch: sh [B,9,3], rotation [B,3,3] (camera -> env-local), and one
    [B,3,H_k,W_k+2] map per Phong exponent with one wrapped column each side."""

    def __init__(self, sh, rotation, phong):
        self.sh = sh
        self.rotation = rotation
        self.phong = phong

    def to_env(self, d):
        b, c, h, w = d.shape
        return torch.matmul(self.rotation, d.reshape(b, c, h * w))

    def diffuse(self, normal):
        b, _, h, w = normal.shape
        e = self.to_env(normal)
        x, y, z = e[:, 0:1], e[:, 1:2], e[:, 2:3]
        basis = torch.cat(
            [
                torch.ones_like(x) * 0.2820948,
                y * 0.4886025,
                z * 0.4886025,
                x * 0.4886025,
                (x * y) * 1.0925484,
                (y * z) * 1.0925484,
                ((z * z) * 3.0 - 1.0) * 0.31539157,
                (x * z) * 1.0925484,
                (x * x - y * y) * 0.5462742,
            ],
            1,
        )
        return torch.matmul(self.sh.transpose(1, 2), basis).reshape(b, 3, h, w)

    def specular(self, normal, k):
        b, _, h, w = normal.shape
        nz = normal[:, 2:3]
        view = torch.tensor([0.0, 0.0, 1.0], device=normal.device, dtype=normal.dtype)
        r = normal * (nz * 2.0) - view.reshape(1, 3, 1, 1).expand(b, 3, h, w)
        e = self.to_env(r)
        x, y, z = e[:, 0:1], e[:, 1:2], e[:, 2:3]
        u = torch.atan2(x, -z) / (2.0 * math.pi)
        u = u - torch.floor(u)
        v = torch.acos(y.clamp(-1.0, 1.0)) / math.pi
        m = self.phong[k]
        width = m.shape[3] - 2
        gx = (u * (2.0 * width) + 2.0) / (width + 2) - 1.0
        gy = v * 2.0 - 1.0
        grid = torch.cat([gx.reshape(b, h, w, 1), gy.reshape(b, h, w, 1)], 3)
        return F.grid_sample(m, grid, mode="bilinear", padding_mode="border", align_corners=False)


class RelightNet(nn.Module):
    """relight.rs RelightNet."""

    def __init__(self, widths, render_net="decomposed"):
        super().__init__()
        self.render_net = render_net
        self.f_n = UNet(3, 6, widths)
        self.f_a = UNet(6, 3, widths)
        self.f_s = UNet(3 + 3 + 15, 5, widths)
        self.f_r = UNet(12, 9 if render_net == "decomposed" else 3, widths)

    def forward(self, inp, mask, light):
        geometry = self.f_n(inp)
        normal = unit(torch.tanh(geometry[:, 0:3]))
        normal_lens = unit(torch.tanh(geometry[:, 3:6]))
        albedo = torch.sigmoid(self.f_a(torch.cat([inp, normal], 1)))

        n = normal.detach()
        diffuse = light.diffuse(n)
        spec = [light.specular(n, k) for k in range(LENS_MAP)]
        spec.append(light.specular(normal_lens.detach(), LENS_MAP))

        # relight.rs: networks see light maps through log1p; shading uses the raw maps.
        weights = torch.softmax(self.f_s(torch.cat([inp, albedo] + [torch.log1p(l) for l in spec], 1)), 1)
        specular = None
        for k, l in enumerate(spec):
            term = l * weights[:, k : k + 1]
            specular = term if specular is None else specular + term

        out = self.f_r(torch.cat([inp, albedo, torch.log1p(diffuse), torch.log1p(specular)], 1))
        if self.render_net == "decomposed":
            c_d = F.softplus(out[:, 0:3], beta=1.0)
            c_s = F.softplus(out[:, 3:6], beta=1.0)
            residual = out[:, 6:9]
            relit = albedo * (c_d * diffuse + c_s * specular) + residual
        else:
            relit, residual = out, None
        return {
            "normal": normal,
            "normal_lens": normal_lens,
            "albedo": albedo,
            "weights": weights,
            "diffuse": diffuse,
            "specular": specular,
            "residual": residual,
            "relit": relit * mask,
        }


class PatchGan(nn.Module):
    """loss.rs PatchGan: 3x (4x4 stride-2 pad-1 conv + leaky_relu 0.2), 3x3 'same' head."""

    def __init__(self, width=32):
        super().__init__()
        w = max(width, 1)
        self.layers = nn.ModuleList(
            [burn_conv(4, w, 4, 2, 1), burn_conv(w, 2 * w, 4, 2, 1), burn_conv(2 * w, 4 * w, 4, 2, 1)]
        )
        self.head = burn_conv(4 * w, 1, 3, padding=1)

    def forward(self, image, mask):
        image = image.clamp_min(0.0) / (image.clamp_min(0.0) + 1.0)
        x = torch.cat([image, mask], 1)
        for layer in self.layers:
            x = F.leaky_relu(layer(x), LEAK)
        return self.head(x)


# loss.rs LossWeights::default()
WEIGHTS = dict(normal=1.0, normal_lens=1.0, albedo=1.0, relit=1.0, residual=0.1, adversarial=0.01)


def symlog(x):
    """loss.rs: sign(x) * log(1 + |x|)."""
    return torch.sign(x) * torch.log1p(torch.abs(x))


def masked_l1(pred, target, mask):
    channels = pred.shape[1]
    num = ((pred - target).abs() * mask).sum()
    den = mask.sum() * channels + 1e-6
    return num / den


def generator_loss(out, t, critic):
    w = WEIGHTS
    total = (
        masked_l1(out["normal"], t["normal"], t["mask"]) * w["normal"]
        + masked_l1(out["normal_lens"], t["normal_lens"], t["mask"]) * w["normal_lens"]
        + masked_l1(out["albedo"], t["albedo"], t["mask"]) * w["albedo"]
        + masked_l1(symlog(out["relit"]), symlog(t["relit"]), t["mask"]) * w["relit"]
    )
    if out["residual"] is not None:
        r = out["residual"]
        total = total + masked_l1(r, torch.zeros_like(r), t["mask"]) * w["residual"]
    if critic is not None and w["adversarial"] > 0.0:
        adv = (critic(out["relit"], t["mask"]) - 1.0).pow(2).mean()
        total = total + adv * w["adversarial"]
    return total


def critic_loss(critic, real, fake, mask):
    r = (critic(real, mask) - 1.0).pow(2).mean()
    f = critic(fake, mask).pow(2).mean()
    return (r + f) * 0.5


def conv_params(cin, cout, k):
    return cin * cout * k * k + cout


def unet_params(cin, cout, widths):
    """Analytic parameter count of unet.rs UNet (cross-check for count_params)."""
    n = 0
    for level, width in enumerate(widths):
        i = cin if level == 0 else widths[level - 1]
        n += conv_params(i, width, 3) + conv_params(width, width, 3)
    for level in range(len(widths) - 1):
        n += conv_params(widths[level + 1] + widths[level], widths[level], 3)
        n += conv_params(widths[level], widths[level], 3)
    return n + conv_params(widths[0], cout, 1)


def relight_params(widths, render_net):
    out = 9 if render_net == "decomposed" else 3
    return sum(unet_params(i, o, widths) for i, o in [(3, 6), (6, 3), (21, 5), (12, out)])


def count_params(module):
    return sum(p.numel() for p in module.parameters())


def make_inputs(batch, size, seed, device):
    """Random tensors of the trainer's shapes (numpy-seeded, so identical on CPU and CUDA)."""
    rng = np.random.default_rng(seed)
    f32 = np.float32

    yy, xx = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5, indexing="ij")
    disc = ((xx - size / 2) ** 2 + (yy - size / 2) ** 2 <= (0.45 * size) ** 2).astype(f32)
    mask = np.broadcast_to(disc, (batch, 1, size, size)).copy()

    def unit_field():
        v = rng.standard_normal((batch, 3, size, size)).astype(f32)
        return v / np.linalg.norm(v, axis=1, keepdims=True).clip(1e-6)

    inp = rng.random((batch, 3, size, size), dtype=f32) * mask
    normal = unit_field()
    normal_lens = unit_field()
    albedo = rng.random((batch, 3, size, size), dtype=f32)
    relit = rng.random((batch, 3, size, size), dtype=f32) * 2.0 * mask

    rot = np.empty((batch, 3, 3), dtype=f32)
    for b in range(batch):
        q, r = np.linalg.qr(rng.standard_normal((3, 3)))
        q = q * np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] = -q[:, 0]
        rot[b] = q
    sh = rng.random((batch, 9, 3), dtype=f32)
    phong = []
    for h, w in PHONG_SIZES:
        m = rng.random((batch, 3, h, w), dtype=f32) * 4.0
        phong.append(np.concatenate([m[..., w - 1 :], m, m[..., :1]], axis=3))  # wrap columns

    t = lambda a: torch.from_numpy(np.ascontiguousarray(a)).to(device)
    light = LightBatch(t(sh), t(rot), [t(p) for p in phong])
    targets = dict(normal=t(normal), normal_lens=t(normal_lens), albedo=t(albedo), relit=t(relit), mask=t(mask))
    return t(inp), targets, light


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch", type=int, default=2)
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--widths", default="32,64,128,256,512")
    p.add_argument("--gan-width", type=int, default=32)
    p.add_argument("--render-net", choices=["decomposed", "blackbox"], default="decomposed")
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--iters", type=int, default=5)
    p.add_argument("--threads", type=int, default=0, help="torch.set_num_threads (0: torch's default)")
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tf32", action="store_true", help="allow TF32 on CUDA (default: plain f32 like Burn)")
    p.add_argument("--amp", choices=["f16", "bf16"], default=None,
                   help="automatic mixed precision: autocast to this type, GradScaler for f16 "
                        "(lightfarm's counterpart: bench_train --precision)")
    a = p.parse_args()

    widths = [int(w) for w in a.widths.split(",") if w.strip()]
    multiple = 1 << max(len(widths) - 1, 0)
    if not widths or a.size < 1 or a.size % multiple:
        sys.exit(f"--size {a.size} must be a positive multiple of {multiple} for widths {widths}")
    if a.iters < 1:
        sys.exit("--iters must be at least 1")
    if a.threads > 0:
        torch.set_num_threads(a.threads)
    device = torch.device(a.device)
    if a.device == "cuda":
        if not torch.cuda.is_available():
            sys.exit("--device cuda: no CUDA device visible to torch")
        precision = "tf32" if a.tf32 else "ieee"
        torch.backends.cudnn.conv.fp32_precision = precision
        torch.backends.cuda.matmul.fp32_precision = precision

    torch.manual_seed(a.seed)
    model = RelightNet(widths, a.render_net).to(device)
    critic = PatchGan(a.gan_width).to(device)
    params = count_params(model)
    expected = relight_params(widths, a.render_net)
    assert params == expected, (params, expected)
    print(f"generator parameters: {params} (widths {widths}, {a.render_net}); "
          f"critic parameters: {count_params(critic)}", file=sys.stderr)

    adam = dict(lr=a.lr, betas=(0.9, 0.999), eps=1e-5, weight_decay=0.0)
    optim = torch.optim.Adam(model.parameters(), **adam)
    critic_optim = torch.optim.Adam(critic.parameters(), **adam)
    inp, targets, light = make_inputs(a.batch, a.size, a.seed, device)

    def sync():
        if device.type == "cuda":
            torch.cuda.synchronize()

    amp_dtype = {"f16": torch.float16, "bf16": torch.bfloat16}.get(a.amp)
    # One scaler for both optimisers, as lightfarm's trainer has one loss scale.
    scaler = torch.amp.GradScaler(device.type, enabled=a.amp == "f16")

    def autocast():
        return torch.autocast(device_type=device.type, dtype=amp_dtype, enabled=amp_dtype is not None)

    def step():
        optim.zero_grad(set_to_none=True)
        with autocast():
            out = model(inp, targets["mask"], light)
            loss = generator_loss(out, targets, critic)
        total = loss.item()
        if not math.isfinite(total):
            sys.exit(f"generator loss diverged: {total}")
        # like Burn, this also fills the critic's grads; they are dropped below
        scaler.scale(loss).backward()

        critic_optim.zero_grad(set_to_none=True)
        with autocast():
            c = critic_loss(critic, targets["relit"], out["relit"].detach(), targets["mask"])
        c.item()
        scaler.scale(c).backward()
        scaler.step(optim)
        scaler.step(critic_optim)
        scaler.update()
        return total

    for _ in range(a.warmup):
        step()
    sync()
    times = []
    for i in range(a.iters):
        sync()
        t0 = time.perf_counter()
        total = step()
        sync()
        times.append(time.perf_counter() - t0)
        print(f"iter {i + 1}/{a.iters}: {times[-1]:.3f} s, loss {total:.4f}", file=sys.stderr)

    print(json.dumps({
        "framework": "pytorch",
        "torch": torch.__version__,
        "device": device.type,
        "batch": a.batch,
        "size": a.size,
        "widths": widths,
        "render_net": a.render_net,
        "amp": a.amp,
        "gan_width": a.gan_width,
        "threads": torch.get_num_threads(),
        "warmup": a.warmup,
        "iters": a.iters,
        "seconds_per_iter_median": statistics.median(times),
        "seconds_per_iter_min": min(times),
        "iters_per_s": a.iters / sum(times),
        "params": params,
    }))


if __name__ == "__main__":
    main()
