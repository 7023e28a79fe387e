"""A full pass of cp_focal's training loader alone, then training steps timed per 100 (argv[1]
steps): whether a step slows over an epoch (shards decompressed later, denormals)."""
import sys, time
from pathlib import Path
exec((Path(__file__).with_name("parts.py")).read_text().split("out = {")[0])
def loader():
    return GroupedLoader(train_ds, sampler=train_ds.group_sampler(mcfg.batch_size, mcfg.scene_group, seed))
t = time.perf_counter(); n = 0
for b in loader(): n += 1
print("full loader pass", n, round(time.perf_counter() - t, 1), "s", flush=True)
model.train(); it = iter(loader())
chunk = []
t0 = time.perf_counter()
for i in range(int(sys.argv[1])):
    T.train_step(model, next(it), opt, loss, cfg)
    if (i + 1) % 100 == 0:
        t1 = time.perf_counter(); chunk.append(round((t1 - t0) / 100 * 1000, 1)); t0 = t1
        print("ms/step per 100:", chunk, flush=True)
