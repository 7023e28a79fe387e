"""Stage train_slide: the chapter 3 slide ConvNet (thesis 3.3.1, Fig. 3.4) trained on
data/ch3_slides -> models/slide_convnet/best.pt; reports/train_slide/: log.csv (per epoch),
metrics.json (validation accuracy, precision, recall, calibration), calibration.png and
candidates.png (thesis Fig. 3.12: candidate slides on validation piles coloured by
probability)."""

from pathlib import Path

from clutterbench.collapse.slide_figure import calibration_figure, candidates_figure
from clutterbench.collapse.slide_train import SlideTrainConfig, train_slide_convnet
from clutterbench.config import BaseConfig, load_section
from clutterbench.data.slide_crops import ScanConfig
from clutterbench.data.slides import load_slide_samples, pile_seed
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json
from clutterbench.models.slide_convnet import load_slide_convnet
from clutterbench.sim.pile_config import PileCameraConfig, PileConfig
from clutterbench.stage import run_stage

REPORT = Path("reports/train_slide")
FIGURE_PILES = 4


def train_slide(params: dict, base: BaseConfig) -> None:
    cfg = load_section(SlideTrainConfig, "yamakuzushi.convnet", params)
    scan = load_section(ScanConfig, "yamakuzushi.scan", params)
    if cfg.net.input_size != scan.crop_px:
        raise ClutterbenchError(
            f"yamakuzushi.convnet.net.input_size {cfg.net.input_size} must equal "
            f"yamakuzushi.scan.crop_px {scan.crop_px}"
        )
    samples = load_slide_samples(Path("data/ch3_slides/samples.npz"))
    metrics = train_slide_convnet(samples, cfg, base.seed, Path("models/slide_convnet"), REPORT)
    calibration_figure(metrics["val"], REPORT / "calibration.png")
    model, _ = load_slide_convnet(Path("models/slide_convnet/best.pt"))
    val_piles = read_json(Path("reports/slides/manifest.json"))["val_piles"][:FIGURE_PILES]
    seeds = [pile_seed(base.seed, "ch3_data", i) for i in val_piles]
    pile = load_section(PileConfig, "yamakuzushi.pile", params)
    camera = load_section(PileCameraConfig, "yamakuzushi.camera", params)
    candidates_figure(model, seeds, pile, camera, scan, REPORT / "candidates.png")
    val = metrics["val"]
    print(
        f"train_slide: best epoch {metrics['best_epoch']} of {metrics['epochs_run']}, "
        f"{metrics['train_s']} s; validation accuracy {val['accuracy']:.3f} "
        f"(precision {val['precision']:.3f}, recall {val['recall']:.3f}, n {val['n']})"
    )


if __name__ == "__main__":
    run_stage(train_slide)
