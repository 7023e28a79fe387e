import torch, time, torch.nn.functional as F
torch.set_num_threads(2)
torch.manual_seed(0)
def bench(f, n=20):
    f(); t=[]
    for _ in range(n):
        t0=time.perf_counter(); f(); t.append(time.perf_counter()-t0)
    return 1e3*min(t)
for shape, size in [((24,3,32,32),(128,128)), ((24,64,16,16),(32,32)), ((24,128,8,8),(16,16))]:
  for dt in [torch.bfloat16]:
    x = torch.randn(shape).to(dt)
    xc = x.contiguous(memory_format=torch.channels_last).requires_grad_()
    xn = x.contiguous().requires_grad_()
    g = torch.randn(shape[0], shape[1], *size).to(dt)
    yc = F.interpolate(xc, size=size, mode="bilinear", align_corners=False)
    yn = F.interpolate(xn, size=size, mode="bilinear", align_corners=False)
    gc = g.contiguous(memory_format=torch.channels_last)
    (gic,) = torch.autograd.grad(yc, xc, gc)
    (gin,) = torch.autograd.grad(yn, xn, g.contiguous())
    print(shape, dt, "fwd equal", torch.equal(yc, yn), "bwd equal", torch.equal(gic, gin), "max bwd diff", (gic.float()-gin.float()).abs().max().item())
    print("  CL fwd %.3f ms  NCHW fwd %.3f ms" % (bench(lambda: F.interpolate(xc.detach(), size=size, mode="bilinear", align_corners=False)), bench(lambda: F.interpolate(xn.detach(), size=size, mode="bilinear", align_corners=False))))
    print("  CL bwd %.3f ms  NCHW bwd %.3f ms" % (bench(lambda: torch.autograd.grad(F.interpolate(xc, size=size, mode="bilinear", align_corners=False), xc, gc)), bench(lambda: torch.autograd.grad(F.interpolate(xn, size=size, mode="bilinear", align_corners=False), xn, g))))
    # route: CL in -> contiguous -> upsample -> CL out
    def route(x):
        return F.interpolate(x.contiguous(), size=size, mode="bilinear", align_corners=False).contiguous(memory_format=torch.channels_last)
    yr = route(xc); (gir,) = torch.autograd.grad(yr, xc, gc)
    print("  route equal fwd", torch.equal(yr, yc), "bwd", torch.equal(gir, gic), "strides", yr.stride()==yc.stride(), "time fwd+bwd %.3f" % bench(lambda: torch.autograd.grad(route(xc), xc, gc)))
