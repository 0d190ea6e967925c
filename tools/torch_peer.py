#!/usr/bin/env python3
"""What a user would write instead of tfmatch, in a few lines of PyTorch, timed on the same device.

The issue on GPU speed compares every tfmatch benchmark with this peer, measured in the same
session on the lent GPU (tools/gpu-check.sh --parts torch): reading both fields (the memory read
bound), host-to-device copies from pageable and from pinned memory, the normal-equation assembly
by bincount, and Pearson and Spearman correlation fields. `--check` first compares the assembly
and the correlations with plain double-precision NumPy on a small problem, so the numbers are
those of correct code.

    python3 tools/torch_peer.py [--device cuda|cpu] [--voxels N] [--tf-size N] [--json FILE] [--check]
"""
import argparse
import json
import sys
import time

import numpy as np
import torch


def sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def best_ms(fn, device, repeats):
    """Best wall time of fn() in milliseconds over `repeats` runs after one warm-up run."""
    fn()
    sync(device)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        sync(device)
        best = min(best, (time.perf_counter() - start) * 1e3)
    return best


def tf_coordinates(values, lo, hi, n):
    """tfmatch's TF lookup (DESIGN.md): t = clamp((v - lo) / (hi - lo)), j = min(floor(t (n-1)), n-2)."""
    t = ((values - lo) / (hi - lo)).clamp(0.0, 1.0)
    x = t * (n - 1)
    j = torch.clamp(torch.floor(x), max=n - 2)
    return j.long(), x - j


def reference_colours(ref, ref_tf):
    """b = T_r(F_r): the reference TF (n x 4) at every reference value (range 0..1 here)."""
    j, w = tf_coordinates(ref, 0.0, 1.0, ref_tf.shape[0])
    return (1 - w)[:, None] * ref_tf[j] + w[:, None] * ref_tf[j + 1]


def assemble(ref, field, ref_tf, n):
    """M = S^T S (diagonal and first off-diagonal) and S^T b of the voxel least-squares problem."""
    b = reference_colours(ref, ref_tf)
    j, w = tf_coordinates(field, field.min(), field.max(), n)
    a, c = 1 - w, w
    diag = torch.bincount(j, weights=a * a, minlength=n) + torch.bincount(j + 1, weights=c * c, minlength=n)
    off = torch.bincount(j, weights=a * c, minlength=n)[: n - 1]
    rhs = torch.stack([torch.bincount(j, weights=a * b[:, k], minlength=n) +
                       torch.bincount(j + 1, weights=c * b[:, k], minlength=n) for k in range(4)], dim=1)
    return diag, off, rhs


def pearson_field(members, reference):
    """members: M x V, reference: M. Per voxel, Pearson's r with the reference series."""
    x = reference - reference.mean()
    y = members - members.mean(dim=0, keepdim=True)
    return (x[:, None] * y).sum(dim=0) / (x.norm() * y.norm(dim=0))


def ranks(values, dim):
    """Ranks 0..M-1 along `dim` by a double argsort (ties broken by order, as a quick peer does)."""
    return values.argsort(dim=dim).argsort(dim=dim).to(values.dtype)


def spearman_field(members, reference):
    return pearson_field(ranks(members, 0), ranks(reference, 0))


def demo_tf(n, device):
    t = torch.linspace(0, 1, n, device=device, dtype=torch.float64)
    rgba = torch.stack([t, 1 - t, 0.5 + 0.5 * torch.sin(6 * t), 0.05 + 0.9 * t * t], dim=1)
    return rgba.float()


def check(device):
    """The peer's methods against double-precision NumPy on 10 007 voxels and 17 members."""
    rng = np.random.default_rng(7)
    ref = rng.random(10007)
    field = 250 + 60 * np.expm1(1.6 * ref) / np.expm1(1.6)
    n = 33
    tf = demo_tf(n, torch.device("cpu")).double().numpy()
    # NumPy, voxel by voxel in double.
    diag, off, rhs = np.zeros(n), np.zeros(n - 1), np.zeros((n, 4))
    lo, hi = field.min(), field.max()
    for r, f in zip(ref, field):
        x = min(max(r, 0.0), 1.0) * (n - 1)
        jr = min(int(np.floor(x)), n - 2)
        b = (1 - (x - jr)) * tf[jr] + (x - jr) * tf[jr + 1]
        x = min(max((f - lo) / (hi - lo), 0.0), 1.0) * (n - 1)
        j = min(int(np.floor(x)), n - 2)
        w = x - j
        diag[j] += (1 - w) ** 2
        diag[j + 1] += w * w
        off[j] += (1 - w) * w
        rhs[j] += (1 - w) * b
        rhs[j + 1] += w * b
    got = assemble(torch.tensor(ref, device=device, dtype=torch.float32),
                   torch.tensor(field, device=device, dtype=torch.float32), torch.tensor(tf, device=device).float(), n)
    worst = max(float(np.max(np.abs(g.double().cpu().numpy() - e) / (np.abs(e) + 1)))
                for g, e in zip(got, (diag, off, rhs)))
    members = rng.standard_normal((17, 301))
    reference = members[:, 5] + 0.1 * rng.standard_normal(17)
    xc = reference - reference.mean()
    yc = members - members.mean(axis=0)
    expected = (xc[:, None] * yc).sum(axis=0) / (np.linalg.norm(xc) * np.linalg.norm(yc, axis=0))
    pearson = pearson_field(torch.tensor(members, device=device).float(), torch.tensor(reference, device=device).float())
    rank = lambda v: v.argsort(axis=0).argsort(axis=0).astype(float)
    rx, ry = rank(reference), rank(members)
    rxc, ryc = rx - rx.mean(), ry - ry.mean(axis=0)
    expected_s = (rxc[:, None] * ryc).sum(axis=0) / (np.linalg.norm(rxc) * np.linalg.norm(ryc, axis=0))
    spearman = spearman_field(torch.tensor(members, device=device).float(), torch.tensor(reference, device=device).float())
    errors = {"assembly_max_relative": worst,
              "pearson_max_abs": float(np.max(np.abs(pearson.double().cpu().numpy() - expected))),
              "spearman_max_abs": float(np.max(np.abs(spearman.double().cpu().numpy() - expected_s)))}
    ok = errors["assembly_max_relative"] < 1e-4 and errors["pearson_max_abs"] < 1e-5 and errors["spearman_max_abs"] < 1e-5
    return ok, errors


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--voxels", type=int, default=480 * 720 * 120, help="voxels per field (default 41.5 M)")
    p.add_argument("--tf-size", type=int, default=64)
    p.add_argument("--correlation", default="10x1760000,100x200000,1000x20000",
                   help="member x voxel sizes of the correlation fields, comma separated")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", help="write the results as JSON to this file ('-': stdout)")
    p.add_argument("--check", action="store_true", help="first compare with double-precision NumPy; exit 1 if off")
    a = p.parse_args()
    device = torch.device(a.device)
    out = {"device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
           "torch": torch.__version__, "voxels": a.voxels, "tf_size": a.tf_size}
    if a.check:
        ok, errors = check(device)
        out["check"] = {"passed": ok, **errors}
        print(f"check against NumPy (double): {'pass' if ok else 'FAIL'} {errors}", file=sys.stderr)
        if not ok:
            json_out(a.json, out)
            return 1

    gen = torch.Generator().manual_seed(1)
    ref_host = torch.rand(a.voxels, generator=gen)
    field_host = 250 + 60 * torch.expm1(1.6 * ref_host) / float(np.expm1(1.6))
    ref = ref_host.to(device)
    field = field_host.to(device)
    bytes_both = 2 * ref.numel() * 4
    read_ms = best_ms(lambda: (ref.sum(), field.sum()), device, a.repeats)
    out["read_both_ms"] = read_ms
    out["read_bytes_per_s"] = bytes_both / (read_ms * 1e-3)
    if device.type == "cuda":  # on the CPU a copy "to the device" is no copy
        out["upload_pageable_bytes_per_s"] = bytes_both / (best_ms(
            lambda: (ref_host.to(device), field_host.to(device)), device, a.repeats) * 1e-3)
        pinned = torch.empty_like(ref_host).pin_memory()
        pinned.copy_(ref_host)
        out["upload_pinned_bytes_per_s"] = ref_host.numel() * 4 / (best_ms(
            lambda: pinned.to(device, non_blocking=True), device, a.repeats) * 1e-3)
    tf = demo_tf(64, device)
    out["assemble_ms"] = best_ms(lambda: assemble(ref, field, tf, a.tf_size), device, a.repeats)
    out["assemble_voxels_per_s"] = a.voxels / (out["assemble_ms"] * 1e-3)
    out["correlation"] = []
    for size in a.correlation.split(","):
        m, v = (int(x) for x in size.split("x"))
        members = torch.rand(m, v, generator=gen).to(device)
        reference = members[:, v // 2].clone()
        for name, fn in (("pearson", pearson_field), ("spearman", spearman_field)):
            ms = best_ms(lambda: fn(members, reference), device, a.repeats)
            out["correlation"].append({"measure": name, "members": m, "voxels": v, "ms": ms, "voxels_per_s": v / (ms * 1e-3)})
        del members
    for k, v in out.items():
        if k != "correlation":
            print(f"{k}: {v}", file=sys.stderr)
    for c in out["correlation"]:
        print(f"{c['measure']} M={c['members']} x {c['voxels']}: {c['voxels_per_s']:.3g} voxels/s", file=sys.stderr)
    json_out(a.json, out)
    return 0


def json_out(target, out):
    if not target:
        return
    text = json.dumps(out, indent=2) + "\n"
    if target == "-":
        sys.stdout.write(text)
    else:
        with open(target, "w") as f:
            f.write(text)


if __name__ == "__main__":
    sys.exit(main())
