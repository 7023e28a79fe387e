"""Box-head variants on ch6's val split only: threshold on half the val scenes, scored on the other half."""
import sys, time, dataclasses
from pathlib import Path
import numpy as np, torch
from clutterbench.config import load_params, load_section
from clutterbench.sim.config import SimConfig
from clutterbench.support.config import SupportEvalConfig
from clutterbench.support.evaluate import split_scenes
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.support import box_train as bt
from clutterbench.support import box_head as bh
from clutterbench.planning.ch6.support import edge_precision_recall

torch.set_num_threads(1)
params = load_params(Path("params.yaml"))
cfg = load_section(SupportEvalConfig, "support", params)
sim = load_section(SimConfig, "sim", params)
read = dict(threshold_m=0.005, min_pixels=cfg.min_pixels, camera=sim.camera, heads=("pull", "pull_collapse"), collapse_free=(0.01, 15.0))
cp = CollapsePredictor.from_checkpoint(Path("models/cp_focal/best.pt"), image_size=sim.camera.image_size)
t = time.time()
train_sc = split_scenes(Path("data/generate"), Path("data/split/ch6.json"), "train", 5000, **read)
val_sc = split_scenes(Path("data/generate"), Path("data/split/ch6.json"), "val", 600, **read)
print("scenes", len(train_sc), len(val_sc), time.time() - t, flush=True)
def pairs_of(scenes):
    out = []
    for sc in scenes:
        if len(sc.ids) > 1:
            out.append((sc, bt.scene_pairs(sc, bt.cp_probs(cp, sc))))
    return out
tr = pairs_of(train_sc); va = pairs_of(val_sc)
print("pairs", time.time() - t, flush=True)
def cat(ps):
    return bt.Pairs(np.concatenate([p.x for _, p in ps]), np.concatenate([p.y for _, p in ps]), None)
half = len(va) // 2
vA, vB = va[:half], va[half:]
def edges_eval(model, ps, head, thr_fn):
    res = []
    for sc, p in ps:
        k = len(sc.ids)
        pr = bh.predict_pairs(model, p.x)
        full = np.zeros((k, k, pr.shape[1]), np.float32)
        full[~np.eye(k, dtype=bool)] = pr
        e = thr_fn(full)
        truth = sc.view(head).true_edges
        pred = {(sc.ids[x], sc.ids[y]) for x, y in zip(*np.nonzero(e)) if x != y}
        res.append(edge_precision_recall(pred, truth))
    a = np.array(res, float)
    return np.nanmean(a[:, 0]), np.nanmean(a[:, 1])
def run(name, n_train, hidden, epochs=60):
    trp = cat(tr[:n_train]); vap = cat(va)
    c = dataclasses.replace(cfg.box_head, hidden=hidden, epochs=epochs)
    model, log, best = bt.train_box_head(trp, vap, c, 0)
    for head in ("pull", "pull_collapse"):
        best_t, best_f = None, -1
        for th in bt.THRESHOLDS:
            P, R = edges_eval(model, vA, head, lambda f: bh.edge_probability(f, head) > th)
            f1 = 2 * P * R / (P + R)
            if f1 > best_f: best_t, best_f = th, f1
        P, R = edges_eval(model, vB, head, lambda f: bh.edge_probability(f, head) > best_t)
        print(f"{name} {head}: thr {best_t:.2f} valB P {P:.3f} R {R:.3f} (best epoch {best})", flush=True)
run("base2000_h64", 2000, 64)
run("all_h64", len(tr), 64)
run("all_h128", len(tr), 128)
