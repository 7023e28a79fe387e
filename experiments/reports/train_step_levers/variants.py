import sys, time, torch, pathlib, tempfile
import torch.nn.functional as F
from clutterbench.bench import train_steps as ts
from clutterbench.config import load_section
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import train_step
from clutterbench.data.dataset import GroupedLoader
import clutterbench.models.collapse_map as cm
torch.set_num_threads(2)
params = ts.default_params("params.yaml")
cfg = load_section(TrainConfig, "train", params)
mcfg = cfg.models[sys.argv[1]]
root = pathlib.Path(tempfile.gettempdir()) / "clutterbench_levers_syn"
orig_up = cm.upsample_to
def up_nchw(x, like):
    size = like if isinstance(like, torch.Size) else like.shape[-2:]
    if x.shape[1] <= 4 and x.is_contiguous(memory_format=torch.channels_last):
        return F.interpolate(x.contiguous(), size=size, mode="bilinear", align_corners=False).contiguous(memory_format=torch.channels_last)
    return orig_up(x, like)
def run(foreach, nchw, steps=45):
    cm.upsample_to = up_nchw if nchw else orig_up
    ds = ts.synthetic_pairs(params, cfg, mcfg, root)
    loader = GroupedLoader(ds, sampler=ds.group_sampler(mcfg.batch_size, mcfg.scene_group, 0))
    model, opt, loss = ts.build_training(cfg, mcfg, cfg.channels_last)
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=mcfg.lr, foreach=foreach)
    n=0; t0=None
    for b in loader:
        train_step(model, b, opt, loss, cfg); n+=1
        if n==5: t0=time.perf_counter()
        if n==steps+5: break
    return (time.perf_counter()-t0)/steps, model.state_dict()
ref=None
for rep in range(2):
  for foreach, nchw in [(None, False), (True, False), (None, True), (True, True)]:
    dt, sd = run(foreach, nchw)
    if ref is None: ref = sd
    print(f"foreach={foreach} nchw_up={nchw} {1e3*dt:.1f} ms/step identical", all(torch.equal(ref[k], sd[k]) for k in ref), flush=True)
