import sys, time, torch, pathlib, tempfile, threading, queue
from clutterbench.bench import train_steps as ts
from clutterbench.config import load_section
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import train_step
from clutterbench.data.dataset import GroupedLoader
torch.set_num_threads(2)
params = ts.default_params("params.yaml")
cfg = load_section(TrainConfig, "train", params)
mcfg = cfg.models["cp_focal"]
root = pathlib.Path(tempfile.gettempdir()) / "clutterbench_levers_syn"
def ahead(it, depth=2):
    q = queue.Queue(depth); end = object()
    def work():
        for x in it: q.put(x)
        q.put(end)
    t = threading.Thread(target=work, daemon=True); t.start()
    while (x := q.get()) is not end: yield x
def run(pref):
    ds = ts.synthetic_pairs(params, cfg, mcfg, root)
    loader = GroupedLoader(ds, sampler=ds.group_sampler(mcfg.batch_size, mcfg.scene_group, 0))
    model, opt, loss = ts.build_training(cfg, mcfg, cfg.channels_last)
    it = iter(loader)
    if pref: it = ahead(it)
    n=0; t0=None
    for b in it:
        train_step(model, b, opt, loss, cfg); n+=1
        if n==5: t0=time.perf_counter()
        if n==65: break
    dt=(time.perf_counter()-t0)/60
    return dt, model.state_dict()
for pref in [False, True, False, True]:
    dt, sd = run(pref)
    if not pref: ref = sd
    print("prefetch", pref, "%.1f ms/step" % (1e3*dt), "identical", all(torch.equal(ref[k], sd[k]) for k in ref))
