"""Times the MVPCC-Net generator forward, or with --train a whole GAN training step, in PyTorch,
for the side-by-side comparison with `mvpcc profile` (same shapes as src/model: 7 planes in, 7
out, V views fused; random weights and input). The training step is mvpcc's (src/model/gan.rs):
the spectrally normalized PatchGAN on real and detached generated views with the hinge loss,
then the generator's loss against the discriminator as it was (its weights get no gradient):
smooth L1 / foreground, occupancy BCE, hinge adversarial, perceptual and style terms on the
discriminator's features, total variation; Adam (beta 0, 0.9) on both.

    python benches/reference/generator_torch.py --threads 2 --config small
    python benches/reference/generator_torch.py --device cuda --config small --train --batch 16

On CUDA, cuDNN picks its fastest kernels (benchmark mode, as Burn's autotune) and convolutions
and matrix products may use TF32 tensor cores (as Burn's CUDA backend does on sm_80+).
"""

import argparse
import statistics
import time

import torch
from torch import nn

PRESETS = {
    # The paper's network as the original code builds it (`mvpcc profile --config original`).
    "original": dict(width=64, res_blocks=8, size=256, padding="reflect"),
    "small": dict(width=32, res_blocks=4, size=128, padding="reflect"),
    "cpu": dict(width=56, res_blocks=6, size=128, padding="zero"),
    "tiny": dict(width=8, res_blocks=1, size=32, padding="reflect"),
    # The built-in model's shape (`mvpcc profile` without --config).
    "builtin": dict(width=48, res_blocks=2, size=128, padding="zero"),
}
DISC_WIDTH = {"tiny": 8}
# mvpcc's LossWeights defaults (the original code's config.yml).
WEIGHTS = dict(l1=50.0, adversarial=0.1, perceptual=0.1, style=250.0, occupancy=0.1, tv=0.1)


def conv(c_in, c_out, k, pad, padding, dilation=1):
    if padding == "reflect" and pad:
        return [nn.ReflectionPad2d(pad), nn.Conv2d(c_in, c_out, k, dilation=dilation)]
    return [nn.Conv2d(c_in, c_out, k, padding=pad, dilation=dilation)]


class Res(nn.Module):
    def __init__(self, c, padding):
        super().__init__()
        self.body = nn.Sequential(
            *conv(c, c, 3, 2, padding, dilation=2), nn.InstanceNorm2d(c), nn.ReLU(True),
            *conv(c, c, 3, 1, padding), nn.InstanceNorm2d(c))

    def forward(self, x):
        return x + self.body(x)


class Generator(nn.Module):
    def __init__(self, width, res_blocks, size, padding, views=4, planes=7):
        super().__init__()
        w = width
        self.views = views
        self.encoder = nn.Sequential(
            *conv(planes, w, 7, 3, padding), nn.InstanceNorm2d(w), nn.ReLU(True),
            nn.Conv2d(w, 2 * w, 4, 2, 1), nn.InstanceNorm2d(2 * w), nn.ReLU(True),
            nn.Conv2d(2 * w, 4 * w, 4, 2, 1), nn.InstanceNorm2d(4 * w), nn.ReLU(True),
            *[Res(4 * w, padding) for _ in range(res_blocks)])
        self.fusion = nn.Sequential(
            nn.Conv2d(views * 4 * w, 4 * w, 3, padding=1), nn.InstanceNorm2d(4 * w), nn.ReLU(True))
        self.decoder = nn.Sequential(
            nn.ConvTranspose2d(8 * w, 2 * w, 4, 2, 1), nn.InstanceNorm2d(2 * w), nn.ReLU(True),
            nn.ConvTranspose2d(2 * w, w, 4, 2, 1), nn.InstanceNorm2d(w), nn.ReLU(True),
            *conv(w, planes, 7, 3, padding))

    def forward(self, x):  # [B, V, 7, S, S]
        b, v, c, s, _ = x.shape
        f = self.encoder(x.reshape(b * v, c, s, s))
        _, k, h, w = f.shape
        fused = self.fusion(f.reshape(b, v * k, h, w))
        fused = fused.unsqueeze(1).expand(b, v, k, h, w).reshape(b * v, k, h, w)
        out = self.decoder(torch.cat([f, fused], 1))
        return torch.cat([(torch.tanh(out[:, :-1]) + 1) / 2, out[:, -1:]], 1)


class Discriminator(nn.Module):
    """70x70 PatchGAN with spectral norm, no bias; returns the logits and hidden features."""

    def __init__(self, width=64, planes=7):
        super().__init__()
        d = width
        layers = [(planes, d, 2), (d, 2 * d, 2), (2 * d, 4 * d, 2), (4 * d, 8 * d, 1), (8 * d, 1, 1)]
        self.convs = nn.ModuleList(
            nn.utils.spectral_norm(nn.Conv2d(i, o, 4, s, 1, bias=False)) for i, o, s in layers)

    def forward(self, x):
        features = []
        for conv in self.convs[:-1]:
            x = nn.functional.leaky_relu(conv(x), 0.2)
            features.append(x)
        return self.convs[-1](x), features


def gram(f):
    n, c, h, w = f.shape
    f = f.reshape(n, c, h * w)
    return f @ f.transpose(1, 2) / (c * h * w)


def disc_input(images, occupancy):
    b, v, c, s, _ = images.shape
    return torch.cat([images * occupancy, occupancy], 2).reshape(b * v, c + 1, s, s)


def train_step(g, d, g_opt, d_opt, x, images, occupancy, size):
    out = g(x)  # [B·V, 7, S, S]
    b, v = x.shape[:2]
    out = out.reshape(b, v, *out.shape[1:])
    pred, logit = out[:, :, :-1], out[:, :, -1:]
    prob = torch.sigmoid(logit)
    fake_in = disc_input(pred, prob)
    real_logits, real_features = d(disc_input(images, occupancy))
    fake_logits, _ = d(fake_in.detach())
    d_loss = (torch.relu(1 - real_logits).mean() + torch.relu(1 + fake_logits).mean()) / 2
    d_opt.zero_grad(set_to_none=True)
    d_loss.backward()
    real_features = [f.detach() for f in real_features]
    for p in d.parameters():
        p.requires_grad_(False)
    logits, features = d(fake_in)
    for p in d.parameters():
        p.requires_grad_(True)
    foreground = occupancy.mean().clamp_min(1e-3)
    l1 = nn.functional.smooth_l1_loss(pred, images) / foreground
    bce = nn.functional.binary_cross_entropy_with_logits(logit, occupancy)
    adversarial = -logits.mean()
    perceptual = sum((f - r).abs().mean() for f, r in zip(features, real_features))
    style = sum((gram(f) - gram(r)).abs().mean() for f, r in zip(features, real_features))
    geometry = pred[:, :, :3].reshape(b * v, 3, size, size)
    tv = ((geometry[:, :, 1:] - geometry[:, :, :-1]).abs().sum()
          + (geometry[:, :, :, 1:] - geometry[:, :, :, :-1]).abs().sum()) / (b * v * 3)
    w = WEIGHTS
    total = (w["l1"] * l1 + w["adversarial"] * adversarial + w["perceptual"] * perceptual
             + w["style"] * style + w["occupancy"] * bce + w["tv"] / size * tv)
    g_opt.zero_grad(set_to_none=True)
    total.backward()
    d_opt.step()
    g_opt.step()
    return total.item(), d_loss.item()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", choices=PRESETS, default="small")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    ap.add_argument("--batch", type=int, default=1, help="objects per forward or step")
    ap.add_argument("--train", action="store_true", help="time whole GAN training steps")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--profile", action="store_true", help="also print torch.profiler's op table")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    dev = torch.device(args.device)
    if args.device == "cuda":
        torch.backends.cudnn.benchmark = True
        torch.backends.cudnn.allow_tf32 = True
        torch.backends.cuda.matmul.allow_tf32 = True
    p = PRESETS[args.config]
    g = Generator(**p).to(dev)
    s = p["size"]
    images = torch.rand(args.batch, 4, 6, s, s, device=dev)
    occupancy = (torch.rand(args.batch, 4, 1, s, s, device=dev) < 0.4).float()
    images = images * occupancy
    seen = occupancy * (torch.rand_like(occupancy) < 0.5).float()
    x = torch.cat([images * seen, seen], 2)

    def sync():
        if args.device == "cuda":
            torch.cuda.synchronize()

    if args.train:
        d = Discriminator(DISC_WIDTH.get(args.config, 64)).to(dev)
        g_opt = torch.optim.Adam(g.parameters(), lr=1e-4, betas=(0.0, 0.9), eps=1e-8)
        d_opt = torch.optim.Adam(d.parameters(), lr=1e-5, betas=(0.0, 0.9), eps=1e-8)

        def run():
            train_step(g, d, g_opt, d_opt, x, images, occupancy, s)
    else:
        g.eval()

        def run():
            with torch.no_grad():
                g(x).sum().item()

    for _ in range(args.warmup):
        run()
    times = []
    for _ in range(args.runs):
        sync()
        t = time.perf_counter()
        run()
        sync()
        times.append((time.perf_counter() - t) * 1e3)
    what = "train_step" if args.train else "forward"
    name = torch.cuda.get_device_name() if args.device == "cuda" else f"{args.threads} threads"
    print(f"{args.config} {what} batch {args.batch}: median {statistics.median(times):.1f} ms over "
          f"{args.runs} runs ({', '.join(f'{t:.0f}' for t in times)}), torch {torch.__version__}, "
          f"{args.device} ({name})")
    if args.profile:
        with torch.profiler.profile() as prof:
            run()
        print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=12))
    print(f"{what}_ms_median={statistics.median(times):.1f}")


if __name__ == "__main__":
    main()
