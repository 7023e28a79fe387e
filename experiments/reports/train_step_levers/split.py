import sys, time, torch, pathlib, tempfile
from clutterbench.bench import train_steps as ts
from clutterbench.config import load_section
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import train_step, batch_logits
torch.set_num_threads(2)
params = ts.default_params("params.yaml")
cfg = load_section(TrainConfig, "train", params)
mcfg = cfg.models[sys.argv[1] if len(sys.argv)>1 else "cp_focal"]
ds = ts.synthetic_pairs(params, cfg, mcfg, pathlib.Path(tempfile.gettempdir()) / "clutterbench_levers_syn")
batch = ts.first_batch(ds, mcfg.batch_size, mcfg.scene_group)
model, opt, loss = ts.build_training(cfg, mcfg, cfg.channels_last)
for _ in range(5): train_step(model, batch, opt, loss, cfg)
T = {"fwd":[], "loss":[], "bwd":[], "opt":[], "data":[]}
sampler = iter(ds.group_sampler(mcfg.batch_size, mcfg.scene_group, 0))
for _ in range(25):
    t0=time.perf_counter(); b = ds.batch(next(sampler)); t1=time.perf_counter()
    logits = batch_logits(model, batch, cfg); t2=time.perf_counter()
    v = loss(logits, batch); t3=time.perf_counter()
    opt.zero_grad(set_to_none=True); v.backward(); t4=time.perf_counter()
    opt.step(); t5=time.perf_counter()
    for k,a,b_ in [("data",t0,t1),("fwd",t1,t2),("loss",t2,t3),("bwd",t3,t4),("opt",t4,t5)]: T[k].append(1e3*(b_-a))
import numpy as np
print({k: round(float(np.median(v)),2) for k,v in T.items()})
