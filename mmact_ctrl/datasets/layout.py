"""LeRobotDataset v3.0: the layout, as LeRobot's own code writes it.

Read from huggingface/lerobot ``src/lerobot/datasets/`` at commit 7427f31 (:data:`LEROBOT_COMMIT`): ``utils.py``
(the paths and templates, ``DEFAULT_FEATURES``, the chunk/file rotation), ``dataset_metadata.py``
(``DatasetInfo.to_dict``: info.json's keys and their order; the episodes parquet's columns), ``dataset_writer.py``
(one parquet row group per episode, the ``huggingface`` schema metadata), ``compute_stats.py`` (the stats and their
quantiles), ``video_utils.py`` (``get_video_info``: the video ``info`` block; ``from_timestamp`` /
``to_timestamp``; the decoder's 1e-4 s tolerance). Where we differ on purpose: h264 instead of AV1 (LeRobot accepts
it), ``from_timestamp`` from a frame count instead of a sum of durations, and the dataset-wide stats of a vector
feature computed from the pooled frames (exact quantiles) where LeRobot takes the envelope of the episodes'
quantiles. LeRobot itself cannot
be installed beside our torch and Python (``../shared/FACTS.md``), so the format is written here from that code with
pyarrow and PyAV, and checked by independent readers (``lerobot-doctor``, PyAV, pyarrow).

::

    meta/info.json                                   the schema: fps, features, totals, path templates
    meta/stats.json                                  per feature: min, max, mean, std, count, q01 ... q99
    meta/tasks.parquet                               index: the task string; column task_index
    meta/episodes/chunk-000/file-000.parquet         one row per episode: length, index range, video ranges, stats
    data/chunk-000/file-000.parquet                  one row per frame
    videos/<camera key>/chunk-000/file-000.mp4       one stream per camera, the episodes one after another
"""

from __future__ import annotations

#: the LeRobot commit whose code this layout was read from (main, 2026-08-23; the last change under
#: ``src/lerobot/datasets/`` before it: 6adf515, 2026-08-13)
LEROBOT_COMMIT = "7427f31801f944f5ec9ce53cda02862ce7d1638b"
FORMAT_SOURCE = ("huggingface/lerobot src/lerobot/datasets/ (utils.py, dataset_metadata.py, dataset_writer.py, "
                 "dataset_reader.py, compute_stats.py, video_utils.py, feature_utils.py)")

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200

INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
TASKS_PATH = "meta/tasks.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"

#: the columns every frame has (LeRobot's DEFAULT_FEATURES)
DEFAULT_FEATURES: dict[str, dict] = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}

#: the quantiles LeRobot's stats carry (pi0.5 normalises with them)
QUANTILES: tuple[float, ...] = (0.01, 0.10, 0.50, 0.90, 0.99)
STAT_NAMES: tuple[str, ...] = ("min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99")

#: feature name prefixes LeRobot gives a meaning to; our extras start with neither
OBSERVATION_PREFIX = "observation."
ACTION_PREFIX = "action"
IMAGES_PREFIX = "observation.images."


def chunk_and_file(file_number: int) -> tuple[int, int]:
    """(chunk_index, file_index) of the ``file_number``-th file of a kind (``CHUNKS_SIZE`` files per chunk)."""
    return file_number // CHUNKS_SIZE, file_number % CHUNKS_SIZE


def check_feature_name(name: str) -> None:
    """A feature name LeRobot can load: no ``/`` (it separates the episodes parquet's nested columns)."""
    if "/" in name or not name:
        raise ValueError(f"feature name {name!r}: LeRobot feature names are non-empty and contain no '/'")
