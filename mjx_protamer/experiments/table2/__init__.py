"""Reproduce the paper's Table II and Figures 1-2 with simulated teachers.

Four conditions with the same seeds and the same hidden teacher rule: DDPG (no feedback), DTK (simulated
keyboard), DTW (simulated speech: the Whisper + sentiment channel, +1/0/-1 through a confusion matrix, long
latency) and DTP (simulated prosody: continuous, noisy).

Outputs in `out`: table2.md and table2.json (the paper's layout, the paper's numbers beside ours),
figure1_training_reward.png (moving average of the training episode return per condition),
figure2_unique_regions.png (box plot of unique regions per test episode), training.csv (every chunk of
every run) and eval_<condition>_seed<k>.json; for `--resume` and the pooled reward-model score, each
condition's reward models (reward_models/<condition>/, orbax) and a sample of its test states
(test_states_<condition>.npz).

The package, bottom up: `config` (the schema and its loader), `report` (statistics over seeds and table2.md),
`artifacts` (the files, figures and body maps of a trained run), `models` (what a finished condition keeps:
agents, reward models, test states) and `run` (training and testing the conditions). Everything callers
import is re-exported here.
"""

from mjx_protamer.experiments.stats import contrast, seed_stats
from mjx_protamer.experiments.table2.artifacts import plot_regions, plot_training, region_frequencies, write_table2
from mjx_protamer.experiments.table2.config import (DEFAULT_CONDITIONS, DEFAULT_CONFIG, Condition, Table2Config,
                                                    load_table2_config)
from mjx_protamer.experiments.table2.models import (load_condition_agents,
                                                    load_condition_models, load_condition_reward_models,
                                                    load_finished_condition, save_condition_models)
from mjx_protamer.experiments.table2.report import (LABELS, PAPER, SELECTION_METRICS, format_markdown,
                                                    reward_preset_name, summarize)
from mjx_protamer.experiments.table2.run import (AT_ONCE, STATE_STRIDE, Trained, make_seed_evaluator, memory_per_seed,
                                                 pooled_corr, run_table2, train_table2)

__all__ = ["AT_ONCE", "DEFAULT_CONDITIONS", "DEFAULT_CONFIG", "LABELS", "PAPER", "SELECTION_METRICS", "STATE_STRIDE",
           "Condition", "Table2Config", "Trained", "contrast", "format_markdown",
           "load_condition_agents", "load_condition_models", "load_condition_reward_models",
           "load_finished_condition", "load_table2_config", "make_seed_evaluator", "memory_per_seed",
           "plot_regions", "plot_training", "pooled_corr", "reward_preset_name", "run_table2",
           "save_condition_models", "seed_stats", "summarize", "train_table2", "region_frequencies",
           "write_table2"]
