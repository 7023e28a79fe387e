"""Where one cp_focal epoch goes on real data (run in a clone with data/generate, models/):
the training loader alone, training steps (the real loader), validation (evaluate_loss)."""
import itertools, sys, tempfile, time
from pathlib import Path
import torch
from clutterbench.config import load_params, load_base, load_section
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse import train as T
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.data.dataset import GroupedLoader
from clutterbench.stage import seed_everything

STEPS = int(sys.argv[1]) if len(sys.argv) > 1 else 120
params = load_params("params.yaml"); base = load_base(params)
seed_everything(base.seed, base.torch_threads)
cfg = load_section(TrainConfig, "train", params)
gen = load_section(GenerateConfig, "generate", params)
name = "cp_focal"; mcfg = cfg.models[name]; ds_name = mcfg.dataset
scratch = Path(tempfile.mkdtemp())
paths = T.TrainPaths(gen_dir=Path("data/generate"), split_file=Path(f"data/split/{ds_name}.json"),
    model_dir=scratch, report_dir=scratch, timing_file=scratch / "t.json")
thr = gen.datasets[ds_name].moved_threshold_m
seed = T.model_seed(base.seed, name)
train_ds, val_ds, size = T._open_splits(name, cfg, thr, seed, paths, label_thresholds(params))
model = T.build_model(mcfg.arch, mcfg.net)
if cfg.channels_last: model = model.to(memory_format=torch.channels_last)
opt, loss, head_loss, schedule = T._optimiser(model, cfg, mcfg)
heads = tuple(mcfg.labels)
out = {"threads": torch.get_num_threads(), "train_pairs": len(train_ds), "val_pairs": len(val_ds)}
def loader():
    return GroupedLoader(train_ds, sampler=train_ds.group_sampler(mcfg.batch_size, mcfg.scene_group, seed))
n_batches = len(loader())
out["train_batches"] = n_batches
t = time.perf_counter(); k = 0
for b in itertools.islice(loader(), STEPS): k += 1
out["loader_s_per_batch"] = (time.perf_counter() - t) / k
model.train(); it = iter(loader())
for _ in range(5): T.train_step(model, next(it), opt, loss, cfg)
t = time.perf_counter()
for _ in range(STEPS): T.train_step(model, next(it), opt, loss, cfg)
out["step_with_loading_s"] = (time.perf_counter() - t) / STEPS
val_loader = GroupedLoader(val_ds, batch_size=max(mcfg.batch_size, 32))
t = time.perf_counter(); k = 0
for b in val_loader: k += 1
out["val_loading_s"] = time.perf_counter() - t
t = time.perf_counter()
T.evaluate_loss(model, val_loader, loss, cfg, cfg.val_threshold, heads, head_loss)
out["validation_s"] = time.perf_counter() - t
out["epoch_estimate_s"] = out["step_with_loading_s"] * n_batches + out["validation_s"]
print(out)
