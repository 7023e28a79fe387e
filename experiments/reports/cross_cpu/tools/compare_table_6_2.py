"""Table 6.2 (support test part) on two machines: device run vs committed (+ the local rerun's per-scene edges).

python compare_table_6_2.py DEVICE_DIR LOCAL_JSONL REF_DIR > out.md   (from the repository root)
DEVICE_DIR: holds support_scenes.jsonl and x/ (data/support, reports/support from support.tar.gz).
Committed: reports/support/scenes.csv of this checkout; REF_DIR: the checkout whose run made
the committed outputs; its data/support/ holds their truth.json and scenes shards.
"""
import glob, io, json, os, sys
import numpy as np
import pandas as pd
import yaml

dev_dir, local_jsonl, ref_dir = sys.argv[1], sys.argv[2], sys.argv[3]
COMMITTED_CSV = "reports/support/scenes.csv"
COMMITTED_TRUTH = os.path.join(ref_dir, "data/support/truth.json")
REF_SHARDS = os.path.join(ref_dir, "data/support/scenes")
from clutterbench.report.config import TABLE_6_2_METHODS as labels  # noqa: E402

def jl(p):
    return {r["scene"]: r for r in map(json.loads, open(p))}

dev, loc = jl(f"{dev_dir}/support_scenes.jsonl"), jl(local_jsonl)
both = sorted(set(dev) & set(loc))
ct = json.load(open(COMMITTED_TRUTH))
dt = json.load(open(f"{dev_dir}/x/data/support/truth.json"))
cc = pd.read_csv(COMMITTED_CSV)
dc = pd.read_csv(f"{dev_dir}/x/reports/support/scenes.csv")
p = print
p(f"scenes: device {len(dev)}, local rerun {len(loc)}, both {len(both)}; committed truth {len(ct['edges'])}")
p(f"device truth.json byte-equal to committed: {open(COMMITTED_TRUTH).read() == open(f'{dev_dir}/x/data/support/truth.json').read()}; "
  f"device scenes.csv byte-equal to committed: {open(COMMITTED_CSV).read() == open(f'{dev_dir}/x/reports/support/scenes.csv').read()}")
p(f"starts: scene_hash equal on {sum(dev[s]['scene_hash'] == loc[s]['scene_hash'] for s in both)}/{len(both)}; "
  f"start=benchmark device {sum(dev[s]['start'] == 'benchmark' for s in both)}, local {sum(loc[s]['start'] == 'benchmark' for s in both)}")
vis = [s for s in both if dev[s]["visible"] != loc[s]["visible"]]
p(f"visible boxes (>= min_pixels) differ in {len(vis)} scenes: {vis}")
p()
p("## Truth (physics), per scene, device vs committed truth.json\n")
p("| truth | scenes equal | scenes differing | differing scenes | committed edges | device edges |")
p("|---|---|---|---|---|---|")
truth_diff = {}
for k in ("edges", "pull_edges", "pull_collapse_edges"):
    d = [int(s) for s in ct[k] if s in dt[k] and sorted(map(tuple, ct[k][s])) != sorted(map(tuple, dt[k][s]))]
    truth_diff[k] = set(d)
    p(f"| {k} | {len(ct[k]) - len(d)} | {len(d)} | {', '.join(map(str, sorted(d))) or '—'} | "
      f"{sum(len(v) for v in ct[k].values())} | {sum(len(v) for v in dt[k].values())} |")
anyt = set().union(*truth_diff.values())
p(f"\nscenes with any truth difference: {len(anyt)}")
# why: the shards' arrays
p("\n## Shard arrays, device vs committed (repro57) shards, scenes differing per array\n")
cnt = {}
for q in sorted(glob.glob(f"{dev_dir}/x/data/support/scenes/shard-*.npz")):
    a, b = np.load(q), np.load(os.path.join(REF_SHARDS, os.path.basename(q)))
    for k in a.files:
        if k == "config_hash":
            continue
        x, y = a[k], b[k]
        if x.dtype.kind == "f":
            eq = [np.array_equal(x[i], y[i], equal_nan=True) for i in range(len(x))]
        else:
            eq = [np.array_equal(x[i], y[i]) for i in range(len(x))]
        cnt[k] = cnt.get(k, 0) + (len(eq) - sum(eq))
p(", ".join(f"`{k}` {v}" for k, v in cnt.items()))
p()
p("## Per method (all 26 of scenes.csv; Table 6.2 rows marked *), on the scenes both ran\n")
p("| method | T6.2 | committed mean P | device mean P | committed mean R | device mean R | committed pooled P | device pooled P | committed pooled R | device pooled R | scenes: inferred edges differ | scenes: row (n_true/n_pred/tp) differs | of those edge diffs, scenes with equal truth & visible |")
p("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
def st(df):
    return (df.precision.mean(), df.recall.mean(), df.tp.sum() / df.n_pred.sum(), df.tp.sum() / df.n_true.sum())
head_of = lambda m: "pull_collapse_edges" if m.startswith("pull_collapse_") else "pull_edges" if m.startswith("pull_") else "edges"
tot_e = set()
for m in cc.method.drop_duplicates():
    c = cc[(cc.method == m) & cc.scene.isin(both)]
    d = dc[(dc.method == m) & dc.scene.isin(both)]
    cs, ds = st(c), st(d)
    ed = [s for s in both if dev[s]["edges"][m] != loc[s]["edges"][m]]
    tot_e |= set(ed)
    rd = (c.set_index("scene")[["n_true", "n_pred", "tp"]].sort_index() != d.set_index("scene")[["n_true", "n_pred", "tp"]].sort_index()).any(axis=1).sum()
    pure = [s for s in ed if s not in truth_diff[head_of(m)] and s not in vis]
    p(f"| {m} | {'*' if m in labels else ''} | {cs[0]:.3f} | {ds[0]:.3f} | {cs[1]:.3f} | {ds[1]:.3f} | {cs[2]:.3f} | {ds[2]:.3f} | {cs[3]:.3f} | {ds[3]:.3f} | {len(ed)} | {rd} | {len(pure)} |")
p(f"\nscenes where any method's inferred edges differ: {len(tot_e)} of {len(both)}")
# local rerun == committed (sanity)
lc = pd.DataFrame([r for s in both for r in loc[s]["rows"]])
p(f"local rerun rows (from its jsonl) equal to committed scenes.csv rows on the scenes both ran: "
  f"{lc.to_csv(index=False).splitlines() == [l for l in open(COMMITTED_CSV).read().splitlines() if l.split(',')[0] == 'scene' or int(l.split(',')[0]) in set(both)]}")
