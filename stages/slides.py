"""Stage slides: the chapter 3 ConvNet dataset (thesis 3.3.2): piles of Shogi pieces, the
raster scan's candidates on pieces, each labelled by simulating its slide ->
data/ch3_slides/samples.npz and reports/slides/manifest.json (counts, the split)."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.data.slide_crops import ScanConfig
from clutterbench.data.slides import SlideDataConfig, generate_slide_dataset
from clutterbench.io import write_json
from clutterbench.parallel import ParallelConfig
from clutterbench.sim.pile_config import PileCameraConfig, PileConfig, SlideConfig
from clutterbench.stage import run_stage


def slides(params: dict, base: BaseConfig) -> None:
    manifest = generate_slide_dataset(
        load_section(SlideDataConfig, "yamakuzushi.data", params),
        load_section(PileConfig, "yamakuzushi.pile", params),
        load_section(SlideConfig, "yamakuzushi.slide", params),
        load_section(PileCameraConfig, "yamakuzushi.camera", params),
        load_section(ScanConfig, "yamakuzushi.scan", params),
        base.seed,
        Path("data/ch3_slides"),
        load_section(ParallelConfig, "parallel", params),
    )
    write_json(Path("reports/slides/manifest.json"), manifest)
    print(
        f"slides: {manifest['slides_simulated']} slides simulated on {manifest['n_piles']} piles "
        f"({manifest['slides_successful']} successful); {manifest['n_samples']} samples kept "
        f"({manifest['n_train']} train / {manifest['n_val']} val)"
    )


if __name__ == "__main__":
    run_stage(slides)
