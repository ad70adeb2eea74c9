#!/usr/bin/python3
"""One BaMbANN fit, spml (LibTorch, C++) vs the same network and schedule in PyTorch.

spml: `spml bench --learners BaMbANN --reps 1` on the dataset (its fit time from
results.csv, its peak memory from the child's rusage). Peer: PyTorch (Debian's python3-torch)
running what learners/torch/bayes_net.cc runs with the defaults — 3 hidden ELU layers (64
units for one output, 128 for more), local reparameterisation, KL weight 1e-3 on the dense
weights, a model layer over 17 whitened columns, learned noise, Adam (eps 1e-7) at 1e-2 with
cosine decay, 3000 steps of 64 rows, 1 thread, then the two passes of 30 weight draws over the
training rows that spml makes (noise recalibration, theta's identification). The peer's regressor is random with the arm's
shape (rows x outputs x 17): the work per step is the same, the numbers are not compared.

    /usr/bin/python3 tools/bench/bnn_torch_peer.py --data out/simdyn-ll.h5 [--spml build/bin/spml]
"""
import argparse
import csv
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

import h5py
import torch
import torch.nn.functional as F


def peer_fit(X, Y, params, steps, batch, lr, kl_weight, seed):
    torch.manual_seed(seed)
    torch.set_num_threads(1)
    n, d = X.shape
    m = Y.shape[1]
    width = 128 if m > 1 else 64
    x = ((X - X.mean(0)) / X.std(0).clamp_min(1e-12)).float()
    y = (Y / Y.square().mean(0).sqrt()).float()
    phi = torch.randn(n, m, params)
    phi2 = phi.square()
    sizes = [d, width, width, width, m]
    blocks, off = [], 0
    for a, b in zip(sizes[:-1], sizes[1:]):
        blocks.append((off, a, b))
        off += a * b + b
    dense = off
    total = dense + params
    mu = torch.cat([torch.empty(a * b + b).uniform_(-1 / math.sqrt(a), 1 / math.sqrt(a)) for _, a, b in blocks] +
                   [torch.zeros(params)]).requires_grad_()
    rho = torch.full((total,), math.log(math.expm1(1e-3))).requires_grad_()
    prior_sigma = torch.cat([torch.full((a * b + b,), 1 / math.sqrt(a)) for _, a, b in blocks] +
                            [torch.full((params,), 10.0)])
    log_noise = torch.full((m,), math.log(1e-2)).requires_grad_()
    opt = torch.optim.Adam([mu, rho, log_noise], lr=lr, eps=1e-7)
    per_epoch = -(-n // batch)
    epochs = max(1, -(-steps // per_epoch))
    warm = 0   # model_warmup's default
    step, n_steps = 0, epochs * per_epoch
    t0 = time.perf_counter()
    for e in range(epochs):
        order = torch.randperm(n)
        for s in range(0, n, batch):
            idx = order[s:s + batch]
            sig = F.softplus(rho)
            var = sig.square()
            h = x[idx]
            if e >= warm:
                for i, (o, a, b) in enumerate(blocks):
                    W, Wv = mu[o:o + a * b].view(a, b), var[o:o + a * b].view(a, b)
                    B, Bv = mu[o + a * b:o + a * b + b], var[o + a * b:o + a * b + b]
                    mean = torch.addmm(B, h, W)
                    h = mean + torch.addmm(Bv, h.square(), Wv).sqrt() * torch.randn_like(mean)
                    if i + 1 < len(blocks):
                        h = F.elu(h)
            else:
                h = torch.zeros(len(idx), m)
            mean = phi[idx] @ mu[dense:]
            h = h + mean + (phi2[idx] @ var[dense:]).sqrt() * torch.randn_like(mean)
            kl = torch.log(prior_sigma) - torch.log(sig) + (var + mu.square()) / (2 * prior_sigma.square()) - 0.5
            klw = (kl_weight * kl[:dense].sum() if e >= warm else 0) + kl[dense:].sum()
            nv = 1e-6 + log_noise.exp()
            loss = (0.5 * (math.log(2 * math.pi) + nv.log() + (y[idx] - h).square() / nv)).sum(1).mean() + klw / n
            opt.zero_grad()
            loss.backward()
            for g in opt.param_groups:
                g["lr"] = 0.5 * lr * (1 + math.cos(math.pi * step / n_steps))
            step += 1
            opt.step()

    # After training spml makes two passes of 30 whole weight draws over the training rows:
    # the noise recalibration (mean and variance of the prediction) and theta's identification
    # (P^T dense per draw). The peer does the same work.
    def dense_draws(rows, w):
        h = rows.unsqueeze(0).expand(w.shape[0], -1, -1)
        for i, (o, a, b) in enumerate(blocks):
            h = torch.baddbmm(w[:, o + a * b:o + a * b + b].unsqueeze(1), h, w[:, o:o + a * b].view(-1, a, b))
            if i + 1 < len(blocks):
                h = F.elu(h)
        return h

    with torch.no_grad():
        w = mu + F.softplus(rho) * torch.randn(30, total)
        for s in range(0, n, 2048):
            h = dense_draws(x[s:s + 2048], w) + torch.einsum("cop,sp->sco", phi[s:s + 2048], w[:, dense:])
            h.mean(0), h.var(0)
        ptd = torch.zeros(params, 30, dtype=torch.float64)
        for s in range(0, n, 2048):
            d = dense_draws(x[s:s + 2048], w).reshape(30, -1).double()
            ptd += phi[s:s + 2048].reshape(-1, params).double().t() @ d.t()
        P = phi.reshape(-1, params).double()
        torch.linalg.lstsq(P.t() @ P, ptd)
    return time.perf_counter() - t0, epochs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--spml", default="build/bin/spml")
    args = ap.parse_args()
    with h5py.File(args.data, "r") as f:
        X = torch.tensor(f["train/X"][:], dtype=torch.float64)
        Y = torch.tensor(f["train/Y"][:], dtype=torch.float64)
    print(f"train split: {X.shape[0]} rows x {X.shape[1]} inputs, {Y.shape[1]} outputs")

    with tempfile.TemporaryDirectory() as out:
        subprocess.run([args.spml, "bench", "--data", args.data, "--learners", "BaMbANN", "--reps", "1",
                        "--out", out], check=True, stdout=subprocess.DEVNULL)
        with open(os.path.join(out, "results.csv")) as f:
            ours = float(next(csv.DictReader(f))["fitsec"])
    spml_peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    peer, epochs = peer_fit(X, Y, 17, 3000, 64, 1e-2, 1e-3, 1)
    peer_peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"BaMbANN fit ({epochs} epochs): spml {ours:.2f} s (peak {spml_peak_mb:.0f} MB, whole spml bench), "
          f"PyTorch {peer:.2f} s (peak {peer_peak_mb:.0f} MB, whole python process); "
          f"PyTorch / spml = {peer / ours:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
