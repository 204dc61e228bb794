"""Times the MVPCC-Net generator forward in PyTorch on the CPU, for the side-by-side comparison
with `cargo bench --bench model` / `mvpcc profile`. Same layer shapes as src/model (7 planes in,
7 out, V views fused), random weights and input.

    python benches/reference/generator_torch.py --threads 2 --config small
"""

import argparse
import statistics
import time

import torch
from torch import nn

PRESETS = {
    "paper": dict(width=64, res_blocks=8, size=256, padding="reflect"),
    "small": dict(width=32, res_blocks=4, size=128, padding="reflect"),
    "cpu": dict(width=56, res_blocks=6, size=128, padding="zero"),
}


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


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", choices=PRESETS, default="small")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--profile", action="store_true", help="also print torch.profiler's op table")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    p = PRESETS[args.config]
    g = Generator(**p).eval()
    x = torch.rand(1, 4, 7, p["size"], p["size"])
    times = []
    with torch.no_grad():
        g(x)
        for _ in range(args.runs):
            t = time.perf_counter()
            g(x)
            times.append((time.perf_counter() - t) * 1e3)
    print(f"{args.config}: median {statistics.median(times):.1f} ms over {args.runs} runs "
          f"({', '.join(f'{t:.0f}' for t in times)}), torch {torch.__version__}, {args.threads} threads")
    if args.profile:
        with torch.no_grad(), torch.profiler.profile() as prof:
            g(x)
        print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=12))
    print(f"forward_ms_median={statistics.median(times):.1f}")


if __name__ == "__main__":
    main()
