import sys, time, torch, pathlib, tempfile
import torch.nn.functional as F
from clutterbench.bench import train_steps as ts
from clutterbench.config import load_section
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import train_step, batch_logits
from clutterbench.collapse import losses
torch.set_num_threads(2)
params = ts.default_params("params.yaml")
cfg = load_section(TrainConfig, "train", params)
mcfg = cfg.models["cp_focal"]
ds = ts.synthetic_pairs(params, cfg, mcfg, pathlib.Path(tempfile.gettempdir()) / "clutterbench_levers_syn")
batch = ts.first_batch(ds, mcfg.batch_size, mcfg.scene_group)
model, opt, loss = ts.build_training(cfg, mcfg, cfg.channels_last)
logits0 = batch_logits(model, batch, cfg).detach()
print(logits0.dtype, logits0.shape, logits0.stride(), batch["collapse"].dtype, batch["collapse"].stride())
def timeit(f, n=20):
    f(); t=[]
    for _ in range(n):
        t0=time.perf_counter(); f(); t.append(time.perf_counter()-t0)
    return 1e3*sorted(t)[n//2]
def fb(lossf):
    x = logits0.clone().requires_grad_()
    v = lossf(x, batch); v.backward(); return v, x.grad
print("autograd loss fwd %.2f ms  fwd+bwd %.2f ms" % (timeit(lambda: loss(logits0, batch)), timeit(lambda: fb(loss))))
fc = losses.FocalConfig()
class Focal(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, t):
        a1, a0, g = fc.alpha_pos, fc.alpha_neg, fc.gamma
        x = x.float(); t = t.float()
        sgn = 2*t - 1
        u = x*sgn
        logp = F.logsigmoid(u)
        p = logp.exp()
        q = 1 - p
        alpha = torch.where(t > 0.5, a1, a0)
        w = alpha * q.pow(g)
        ctx.save_for_backward(sgn, p, logp, alpha)
        ctx.n = x.numel(); ctx.dt = x.dtype
        return -(w*logp).sum()/x.numel()
    @staticmethod
    def backward(ctx, go):
        sgn, p, logp, alpha = ctx.saved_tensors
        g = fc.gamma; q = 1-p
        d = alpha * q.pow(g) * (g*p*logp - q) * sgn * (go/ctx.n)
        return d, None
def focal_all(x, b):
    return Focal.apply(x, b["collapse"])*3  # approx: one mean over all heads x3
print("custom fwd+bwd %.2f ms" % timeit(lambda: fb(focal_all)))
v1, g1 = fb(loss); v2, g2 = fb(focal_all)
print("value", v1.item(), v2.item(), "grad maxrel", ((g1.float()-g2.float()).abs().max()/g1.float().abs().max()).item())
cl = torch.compile(loss)
print("compiled fwd+bwd %.2f ms" % timeit(lambda: fb(cl)))
v3, g3 = fb(cl); print("compiled value", v3.item(), "grad maxrel", ((g1.float()-g3.float()).abs().max()/g1.float().abs().max()).item())
ln = logits0.contiguous()
def fbn(lossf):
    x = logits0.clone().requires_grad_()
    v = lossf(x.contiguous(), batch); v.backward(); return v, x.grad
print("NCHW logits: fwd+bwd %.2f ms" % timeit(lambda: fbn(loss)))
v4, g4 = fbn(loss); print("NCHW value", v4.item(), v1.item(), "value equal", torch.equal(v4, v1), "grad equal", torch.equal(g4, g1))
