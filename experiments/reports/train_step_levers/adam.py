import sys, time, torch, pathlib, tempfile, copy
from clutterbench.bench import train_steps as ts
from clutterbench.config import load_section
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import train_step
torch.set_num_threads(2)
params = ts.default_params("params.yaml")
cfg = load_section(TrainConfig, "train", params)
mcfg = cfg.models["cp_focal"]
ds = ts.synthetic_pairs(params, cfg, mcfg, pathlib.Path(tempfile.gettempdir()) / "clutterbench_levers_syn")
sampler = iter(ds.group_sampler(mcfg.batch_size, mcfg.scene_group, 0))
batches = [ds.batch(next(sampler)) for _ in range(6)]
def run(**kw):
    model, _, loss = ts.build_training(cfg, mcfg, cfg.channels_last)
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=mcfg.lr, **kw)
    for b in batches: train_step(model, b, opt, loss, cfg)
    t=[]
    for b in batches*3:
        t0=time.perf_counter(); opt.step(); t.append(time.perf_counter()-t0)
    # restore? no: steps above changed weights; compare state after first 6 only
    return model, min(t)
ref, tref = None, None
for kw in [{}, {"foreach": False}, {"foreach": True}, {"fused": True}]:
    model, _, loss = ts.build_training(cfg, mcfg, cfg.channels_last)
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=mcfg.lr, **kw)
    for b in batches: train_step(model, b, opt, loss, cfg)
    sd = {k: v.clone() for k, v in model.state_dict().items()}
    t=[]
    for _ in range(15):
        t0=time.perf_counter(); opt.step(); t.append(time.perf_counter()-t0)
    if ref is None: ref = sd
    same = all(torch.equal(ref[k], sd[k]) for k in ref)
    print(kw, "opt.step best %.2f ms" % (1e3*min(t)), "identical:", same)
