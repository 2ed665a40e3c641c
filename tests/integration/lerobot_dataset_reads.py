"""Run in .venv-lerobot by test_lerobot_export.py: lerobot 0.4.4's own LeRobotDataset loads a
dataset written by ``fxis export --lerobot`` from its local root (no hub) and decodes every
frame of every camera through its own decoder (torchcodec), whose check that each decoded
frame's timestamp is within ``tolerance_s`` of the one asked for is LeRobot's; prints one
JSON object (what it saw) for the test to check.

    .venv-lerobot/bin/python tests/integration/lerobot_dataset_reads.py '{"root": "OUT", "repo_id": "fxis/x"}'

lerobot.datasets imports torchvision only for image transforms (PIL image features and
training augmentations, neither used here). PyPI's torchvision wheels are built against CUDA
torch and do not import beside the CPU torch the Makefile installs; when that import fails,
a stand-in without those transforms takes its place, and says so in the output.
"""

import importlib.machinery
import json
import sys
import types


def _torchvision_or_stand_in() -> bool:
    try:
        import torchvision  # noqa: F401
    except (ImportError, RuntimeError):
        stand_in = types.ModuleType("torchvision")
        stand_in.__spec__ = importlib.machinery.ModuleSpec("torchvision", None)  # for importlib.util.find_spec
        stand_in.transforms = types.SimpleNamespace()  # utils.py imports it; video features never use it
        sys.modules["torchvision"] = stand_in
        return False
    return True


def _stamp(image) -> int | None:
    """The frame id the synthetic camera drew into the picture (channels first, in [0, 1])."""
    import numpy as np

    from fxis_shm import read_stamp

    return read_stamp(np.ascontiguousarray((image[0] * 255).round().byte().numpy()))


def main(spec: dict) -> dict:
    real_torchvision = _torchvision_or_stand_in()
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset(spec["repo_id"], root=spec["root"], video_backend="torchcodec")
    seen: dict = {"torchvision": real_torchvision, "fps": dataset.fps, "tolerance_s": dataset.tolerance_s}
    seen |= {"num_frames": dataset.num_frames, "num_episodes": dataset.num_episodes}
    seen["video_keys"] = list(dataset.meta.video_keys)
    seen["features"] = sorted(dataset.features)
    seen["tasks"] = list(dataset.meta.tasks.index)
    items = []
    for i in range(len(dataset)):
        item = dataset[i]  # decodes each camera's frame at item["timestamp"], within tolerance_s
        row = {key: item[key].item() for key in ("timestamp", "frame_index", "index", "episode_index")}
        row["task"] = item["task"]
        row["shapes"] = {key: list(item[key].shape) for key in dataset.meta.video_keys}
        row["stamps"] = {key: _stamp(item[key]) for key in dataset.meta.video_keys}
        row["fxis"] = {key: int(item[key].item()) for key in item if key.startswith("observation.fxis.")}
        items.append(row)
    seen["items"] = items
    return seen


if __name__ == "__main__":
    print(json.dumps(main(json.loads(sys.argv[1]))))
