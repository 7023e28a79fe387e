"""Stage trials_ch3: the chapter 3 Yamakuzushi games of every variant (thesis Fig. 3.15) in
one pool of workers -> one record per game (reports/trials_ch3/records.jsonl), one per slide
(reports/trials_ch3/slides.jsonl), a summary row per variant (summary.csv) and one MCAP per
variant with every step (data/trials_ch3/<variant>/episodes.mcap). Every variant plays the
same piles, drawn from their own seed stream (ch3_games), never a dataset's."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.data.slides import pile_seed
from clutterbench.io import write_json, write_text
from clutterbench.parallel import ParallelConfig
from clutterbench.stage import run_stage
from clutterbench.trials.ch3.config import CONVNET_VARIANTS, Ch3Config
from clutterbench.trials.ch3.games import ch3_jobs, run_ch3_game, slide_rows
from clutterbench.trials.core.harness import run_episodes, write_mcap
from clutterbench.trials.core.records import write_records
from clutterbench.trials.core.stats import aggregate_games

OUT = Path("reports/trials_ch3")
DATA = Path("data/trials_ch3")
MODEL = Path("models/slide_convnet/best.pt")


def trials_ch3(params: dict, base: BaseConfig) -> None:
    cfg = load_section(Ch3Config, "yamakuzushi", params)
    model = None
    if set(CONVNET_VARIANTS) & set(cfg.games.variants):  # either reads the ConvNet
        from clutterbench.models.slide_convnet import load_slide_convnet

        net, _ = load_slide_convnet(MODEL)  # one clear error before any worker starts
        if net.cfg.input_size != cfg.scan.crop_px:
            from clutterbench.errors import ClutterbenchError

            raise ClutterbenchError(
                f"{MODEL} takes {net.cfg.input_size} px crops, yamakuzushi.scan.crop_px is "
                f"{cfg.scan.crop_px}; rerun train_slide"
            )
        model = str(MODEL)
    collapse_free = load_section(CollapseFreeConfig, "trials.collapse_free", params)
    jobs = ch3_jobs(
        cfg=cfg,
        seed_of=lambda g: pile_seed(base.seed, "ch3_games", g),
        model=model,
        collapse_free=collapse_free,
    )
    parallel = load_section(ParallelConfig, "parallel", params)
    results = run_episodes("trials_ch3", run_ch3_game, jobs, cfg.games.workers, parallel)
    records = [r.record for r in results]
    write_records(OUT / "records.jsonl", records)
    write_records(OUT / "slides.jsonl", slide_rows(records))
    for variant in cfg.games.variants:
        mine = [r for r in results if r.record["condition"] == variant]
        about = {"condition": variant, "scale": base.scale, "games": str(len(mine))}
        write_mcap(DATA / variant / "episodes.mcap", mine, about)
    summary = aggregate_games(records)
    write_text(OUT / "summary.csv", summary.to_csv(index=False))
    write_json(OUT / "totals.json", {"scale": base.scale, "games": len(records)})
    for row in summary.itertuples():
        print(
            f"{row.condition}: {row.mean_pieces:.2f} pieces per game, per slide "
            f"{row.step_success_k}/{row.step_success_n}"
        )


if __name__ == "__main__":
    run_stage(trials_ch3)
