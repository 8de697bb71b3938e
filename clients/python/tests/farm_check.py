"""The Python client against a live farm, driven by the Rust test tests/python_client.rs (which
starts an in-process coordinator and a render worker, then checks what this script wrote).

Usage: farm_check.py ADDRESS TOKEN SPEC OUT_DIR TRAINER_ADDRESS

Submits SPEC, watches the job to completion, streams every sample once (a first stream stopped
after two samples, then resumed from its cursor), writes each sample's arrays as .npy and its
metadata as JSON under OUT_DIR/INDEX/ for the Rust side to compare with its own decoder and
`spec expand`; then streams the job again through a coordinator restart (the Rust side
restarts it on the line "RESTART ME"), runs the IterableDataset with 2 workers x 2 ranks (when
torch is installed), trains on the job with the trainer service and relights a sample, and
writes the error messages of a wrong token, an unknown job and a bad
spec to OUT_DIR/errors.json.
"""

import json
import sys
import time
from pathlib import Path

import numpy as np

import lightfarm


def say(line):
    print(line, flush=True)


def main():
    address, token, spec, out = sys.argv[1], sys.argv[2], sys.argv[3], Path(sys.argv[4])
    client = lightfarm.Client(address, token, trainer=sys.argv[5])
    assert client.server_info().protocol_version == lightfarm.PROTOCOL_VERSION

    job = client.submit(spec)
    states = [lightfarm.job_state(j) for j in client.watch(job.id)]
    last = client.job(job.id)
    assert lightfarm.job_state(last) == "completed", (states, last)
    say(f"job {job.id} completed: {len(states)} updates watched")

    # A stream stopped after two samples and resumed from its cursor.
    first = lightfarm.SampleStream(client, job.id, split="", follow=False)
    seen = []
    for s in first:
        seen.append(s)
        if len(seen) == 2:
            break
    rest = list(lightfarm.SampleStream(client, job.id, split="", follow=False, cursor=first.cursor))
    samples = seen + rest
    indices = [s.index for s in samples]
    assert sorted(indices) == list(range(job.count)), indices
    sequences = [s.sequence for s in samples]
    assert sequences == sorted(set(sequences)), sequences
    for s in samples:
        d = out / str(s.index)
        d.mkdir(parents=True, exist_ok=True)
        for name, a in s.arrays.items():
            np.save(d / f"{name}.npy", a)
        (d / "meta.json").write_text(json.dumps({"split": s.split, "metadata": s.metadata}))
    say(f"streamed {len(samples)} samples, resumed after 2 at cursor {first.cursor}")

    # Following a stream through a coordinator restart.
    again = lightfarm.SampleStream(client, job.id, split="", follow=True, passes=["mask"])
    got = []
    for s in again:
        got.append(s.index)
        if len(got) == 1:
            say("RESTART ME")
            sys.stdin.readline()  # the coordinator is down now; it comes back after a while
    assert sorted(got) == list(range(job.count)), got
    assert again.retries >= 1, "the restart was not noticed"
    say(f"streamed {len(got)} samples across a coordinator restart ({again.retries} retries)")

    try:
        import torch  # noqa: F401
    except ImportError:
        say("no torch: the IterableDataset check is skipped")
    else:
        from torch.utils.data import DataLoader
        from lightfarm.torch import StreamingDataset

        yielded = []
        for rank in range(2):
            ds = StreamingDataset(address, job.id, token, split="", passes=["lit0", "mask"],
                                  rank=rank, world_size=2, cache_dir=str(out / "cache"))
            for batch in DataLoader(ds, batch_size=None, num_workers=2):
                assert tuple(batch["lit0"].shape[:1]) == (3,), batch["lit0"].shape
                assert json.loads(batch["metadata"])["sample"]["index"] == int(batch["index"])
                yielded.append(int(batch["index"]))
        assert sorted(yielded) == list(range(job.count)), yielded
        cached = sorted(p.name for p in (out / "cache").rglob("*.exr"))
        assert len(cached) == job.count, cached
        say(f"IterableDataset: 2 ranks x 2 workers yielded {len(yielded)} samples once each")

    # Training on the job straight from the farm, then relighting one of its samples.
    farm = "farm://" + address.split("://", 1)[-1] + "/" + job.id
    config = {"crop": 16, "checkpoint_every": 1, "loader_threads": 1, "vgg_weights": "none",
              "net": {"widths": [8, 16, 32], "critic_width": 8}}
    train = client.submit_train(farm, config, steps=2, batch=1, split="all")
    deadline = time.monotonic() + 600
    while True:
        now = {j.id: j for j in client.train_jobs()}[train.id]
        if now.state in (3, 4, 5):  # completed, failed, cancelled
            break
        assert time.monotonic() < deadline, "the train job did not end"
        time.sleep(0.5)
    assert now.state == 3 and now.step == 2, now
    info, exr = client.get_sample(job.id, 0)
    hdri = json.loads(info.metadata_json)["sample"]["lighting"][1]["hdri"]
    relit = client.relight(train.id, exr, hdri, rotation_deg=30.0, no_matte=True)
    assert relit.relit_png.startswith(b"\x89PNG") and (relit.width, relit.height) == (16, 16), relit.width
    say(f"trained {train.id} on {farm} and relit sample 0 under {hdri}")

    errors = {}
    try:
        lightfarm.Client(address, "not-the-token").jobs()
    except lightfarm.Unauthenticated as e:
        errors["wrong_token"] = str(e)
    try:
        client.job("no-such-job")
    except lightfarm.NotFound as e:
        errors["unknown_job"] = str(e)
    bad = out / "bad.toml"
    bad.write_text('name = "bad"\ncount = 2\nwidth = 16\nheight = 16\nspp = 1\nhair_style = "x"\n')
    try:
        client.submit(bad)
    except lightfarm.InvalidArgument as e:
        errors["bad_spec"] = str(e)
    try:
        lightfarm.SampleStream(client, "no-such-job")
    except lightfarm.NotFound as e:
        errors["stream_unknown_job"] = str(e)
    (out / "errors.json").write_text(json.dumps(errors))
    say("done")


if __name__ == "__main__":
    main()
