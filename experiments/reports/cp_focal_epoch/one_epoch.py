"""train_model itself for one epoch of cp_focal, its phases timed by wrapping."""
import dataclasses, tempfile, time
from pathlib import Path
from clutterbench.config import load_params, load_base, load_section
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse import train as T
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.stage import seed_everything
import torch

params = load_params("params.yaml"); base = load_base(params)
seed_everything(base.seed, base.torch_threads)
cfg = load_section(TrainConfig, "train", params)
gen = load_section(GenerateConfig, "generate", params)
name = "cp_focal"; mcfg = cfg.models[name]
cfg = dataclasses.replace(cfg, models={**cfg.models, name: dataclasses.replace(mcfg, epochs=1)})
acc = {}
def timed(fn, key):
    def wrap(*a, **k):
        t = time.perf_counter(); r = fn(*a, **k); acc[key] = acc.get(key, 0) + time.perf_counter() - t; return r
    return wrap
T.evaluate_loss = timed(T.evaluate_loss, "validation")
T._write_epoch = timed(T._write_epoch, "write_epoch")
T._train_epoch = timed(T._train_epoch, "train_epoch")
T.train_step = timed(T.train_step, "train_step")
T.save_checkpoint = timed(T.save_checkpoint, "checkpoint")
out = Path(tempfile.mkdtemp())
paths = T.TrainPaths(gen_dir=Path("data/generate"), split_file=Path(f"data/split/{mcfg.dataset}.json"),
    model_dir=out, report_dir=out, timing_file=out / "t.json")
t = time.perf_counter()
T.train_model(name, cfg, gen.datasets[mcfg.dataset].moved_threshold_m, base.seed, paths, label_thresholds(params))
acc["total"] = time.perf_counter() - t
print({k: round(v, 1) for k, v in acc.items()}, "threads", torch.get_num_threads())
