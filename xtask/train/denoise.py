"""Trains the project's denoiser and exports it to ONNX (run by `cargo xtask train-models`).

A residual DnCNN-style network (5 conv layers, 16 channels, 3x3, ReLU; the output
is the input minus the predicted noise), trained on CPU with Adam on the pairs
`examples/train_data.rs` writes (crops of real photographs, noise from the
project's own noise model). Seeded and single-threaded-deterministic; the exported
graph has a fixed input shape (tract optimises fixed shapes ~2.6x better).

Contract (src/analysis/onnx.rs, role `denoise`): input `noisy` f32 [1,3,H,W], the
frame's RGB as the fit sees it, values in [0,1]; output `clean` f32 [1,3,H,W], same
space. Zero padding: the tiling provider discards a margin at tile borders.

Usage: python denoise.py DATA_DIR OUT.onnx METRICS.json [--epochs N] [--seed S] [--tile PX]
"""

import argparse
import json
import time

import numpy as np
import torch
import torch.nn as nn


class Denoiser(nn.Module):
    def __init__(self, width=16, depth=5):
        super().__init__()
        layers = [nn.Conv2d(3, width, 3, padding=1), nn.ReLU()]
        for _ in range(depth - 2):
            layers += [nn.Conv2d(width, width, 3, padding=1), nn.ReLU()]
        layers += [nn.Conv2d(width, 3, 3, padding=1)]
        self.body = nn.Sequential(*layers)

    def forward(self, noisy):
        # Residual learning: the network predicts the noise, which is small and
        # zero-mean, so it trains far faster than predicting the image.
        return noisy - self.body(noisy)


def psnr(a, b):
    mse = float(((a - b) ** 2).mean())
    return 10.0 * np.log10(1.0 / max(mse, 1e-12))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("data")
    ap.add_argument("out")
    ap.add_argument("metrics")
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--seed", type=int, default=20261123)
    ap.add_argument("--tile", type=int, default=128)
    args = ap.parse_args()

    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    torch.set_num_threads(2)
    torch.use_deterministic_algorithms(True)

    load = lambda n: torch.from_numpy(np.load(f"{args.data}/{n}.npy"))
    xc, xn = load("train_clean"), load("train_noisy")
    vc, vn = load("val_clean"), load("val_noisy")
    print(f"train {tuple(xn.shape)}, val {tuple(vn.shape)}", flush=True)

    net = Denoiser()
    params = sum(p.numel() for p in net.parameters())
    opt = torch.optim.Adam(net.parameters(), lr=2e-3)
    steps_per_epoch = (len(xn) + 31) // 32
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=2e-3, total_steps=args.epochs * steps_per_epoch)
    t0 = time.time()
    for epoch in range(args.epochs):
        net.train()
        perm = torch.randperm(len(xn))
        total = 0.0
        for i in range(0, len(xn), 32):
            idx = perm[i : i + 32]
            opt.zero_grad()
            loss = ((net(xn[idx]) - xc[idx]) ** 2).mean()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss) * len(idx)
        net.eval()
        with torch.no_grad():
            vo = torch.cat([net(vn[i : i + 64]) for i in range(0, len(vn), 64)])
        print(
            f"epoch {epoch + 1}/{args.epochs}: train mse {total / len(xn):.3e}, "
            f"val psnr {psnr(vn.numpy(), vc.numpy()):.2f} -> {psnr(vo.numpy(), vc.numpy()):.2f} dB "
            f"({time.time() - t0:.0f} s)",
            flush=True,
        )

    # Residual noise the denoiser leaves, relative to the noise it was given
    # (validation pairs with noise): what the noise fit must allow for.
    with torch.no_grad():
        vo = torch.cat([net(vn[i : i + 64]) for i in range(0, len(vn), 64)]).numpy()
    vcn, vnn = vc.numpy(), vn.numpy()
    given = ((vnn - vcn) ** 2).mean(axis=(1, 2, 3))
    left = ((vo - vcn) ** 2).mean(axis=(1, 2, 3))
    noisy = given > 1e-7
    ratio = float(np.median(left[noisy] / given[noisy]))

    x = torch.zeros(1, 3, args.tile, args.tile)
    torch.onnx.export(
        net, (x,), args.out, input_names=["noisy"], output_names=["clean"], dynamo=False, opset_version=17
    )
    metrics = {
        "role": "denoise",
        "architecture": "residual CNN, 5 conv 3x3 layers, 16 channels, ReLU, zero padding",
        "parameters": params,
        "input": {"name": "noisy", "shape": [1, 3, args.tile, args.tile]},
        "output": {"name": "clean", "shape": [1, 3, args.tile, args.tile]},
        "seed": args.seed,
        "epochs": args.epochs,
        "train_pairs": len(xn),
        "val_pairs": len(vn),
        "val_psnr_noisy_db": psnr(vnn, vcn),
        "val_psnr_denoised_db": psnr(vo, vcn),
        "val_median_residual_variance_ratio": ratio,
        "train_time_s": round(time.time() - t0, 1),
        "torch": torch.__version__,
    }
    with open(args.metrics, "w") as f:
        json.dump(metrics, f, indent=2)
    print(json.dumps(metrics, indent=2))


if __name__ == "__main__":
    main()
