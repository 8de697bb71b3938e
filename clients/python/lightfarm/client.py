"""`Client`: the operations of the `lightfarm` CLI from Python, over the same gRPC API
(`proto/lightfarm/v1`), with the servers' own error texts."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Iterator, List, Optional, Union

import grpc

from . import errors
from ._protocol import PROTOCOL_VERSION


def _stubs():
    try:
        from .v1 import jobs_pb2, jobs_pb2_grpc, samples_pb2, samples_pb2_grpc
        from .v1 import trainer_pb2, trainer_pb2_grpc, common_pb2
    except ImportError as e:  # a source checkout on sys.path instead of an installed package
        raise ImportError(
            "the lightfarm gRPC stubs are generated when the package is built: "
            "pip install ./clients/python (from the lightfarm repository)"
        ) from e
    return jobs_pb2, jobs_pb2_grpc, samples_pb2, samples_pb2_grpc, trainer_pb2, trainer_pb2_grpc, common_pb2


def _channel(address: str, tls_ca: Optional[str]) -> grpc.Channel:
    """A channel to `address` (`http://host:port`, `https://host:port` or `host:port`)."""
    target = address
    secure = tls_ca is not None
    for scheme in ("http://", "https://"):
        if target.startswith(scheme):
            secure = secure or scheme == "https://"
            target = target[len(scheme):]
    target = target.rstrip("/")
    if not target or "/" in target:
        raise ValueError(f"address {address!r} is not like http://host:7070")
    options = [
        ("grpc.max_receive_message_length", 64 << 20),
        ("grpc.max_send_message_length", 256 << 20),
    ]
    if secure:
        root = Path(tls_ca).read_bytes() if tls_ca else None
        return grpc.secure_channel(target, grpc.ssl_channel_credentials(root), options)
    return grpc.insecure_channel(target, options)


JOB_STATES = {0: "unspecified", 1: "running", 2: "paused", 3: "cancelled", 4: "completed", 5: "failed"}


def job_state(job) -> str:
    """A Job message's state as the CLI names it."""
    return JOB_STATES.get(job.state, "unspecified")


def finished(job) -> bool:
    """Whether a job will commit no more samples."""
    return job_state(job) in ("cancelled", "completed", "failed")


class Client:
    """A connection to a coordinator (and, for training and relighting, a trainer service).

    `address` is the coordinator's gRPC address (`http://host:7070`), `token` its bearer
    token (default: `$LIGHTFARM_TOKEN`), `tls_ca` the CA certificate (PEM) of a TLS
    coordinator. `trainer` is the trainer service's address (default: `$LIGHTFARM_TRAINER`),
    reached with `trainer_token` (default: `token`).
    """

    def __init__(
        self,
        address: str = "http://127.0.0.1:7070",
        token: Optional[str] = None,
        tls_ca: Optional[str] = None,
        trainer: Optional[str] = None,
        trainer_token: Optional[str] = None,
    ):
        (self._jobs_pb, jobs_grpc, self._samples_pb, samples_grpc,
         self._trainer_pb, trainer_grpc, _) = _stubs()
        token = token if token is not None else os.environ.get("LIGHTFARM_TOKEN")
        if not token:
            raise ValueError("a bearer token is required: pass token= or set LIGHTFARM_TOKEN")
        self.address = address
        self._metadata = (("authorization", f"Bearer {token}"),)
        self._channel = _channel(address, tls_ca)
        self._jobs = jobs_grpc.JobsStub(self._channel)
        self._samples = samples_grpc.SamplesStub(self._channel)
        self.trainer_address = trainer or os.environ.get("LIGHTFARM_TRAINER")
        self._trainer = None
        if self.trainer_address:
            self._trainer_metadata = (("authorization", f"Bearer {trainer_token or token}"),)
            self._trainer = trainer_grpc.TrainerStub(_channel(self.trainer_address, tls_ca))
        self._checked = False

    def close(self):
        self._channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ plumbing

    def _call(self, method, request, service: str = "coordinator", timeout: Optional[float] = 60.0):
        if service == "coordinator":
            self._check_protocol()
        metadata = self._metadata if service == "coordinator" else self._trainer_metadata
        address = self.address if service == "coordinator" else self.trainer_address
        try:
            return method(request, metadata=metadata, timeout=timeout)
        except grpc.RpcError as e:
            raise errors.from_rpc(e, address, service) from None

    def _check_protocol(self):
        if self._checked:
            return
        try:
            info = self._jobs.GetServerInfo(
                self._jobs_pb.ServerInfoRequest(), metadata=self._metadata, timeout=30.0
            )
        except grpc.RpcError as e:
            if e.code() == grpc.StatusCode.UNIMPLEMENTED:
                raise errors.ProtocolMismatch(
                    f"the coordinator at {self.address} predates protocol versions; this "
                    f"client speaks version {PROTOCOL_VERSION}: upgrade the coordinator or "
                    "install the client from its source tree (pip install ./clients/python)"
                ) from None
            raise errors.from_rpc(e, self.address) from None
        if info.protocol_version != PROTOCOL_VERSION:
            raise errors.ProtocolMismatch(
                f"the coordinator at {self.address} (lightfarm {info.server_version}) speaks "
                f"protocol version {info.protocol_version}, this client version "
                f"{PROTOCOL_VERSION}: install the client from the coordinator's source tree "
                "(pip install ./clients/python)"
            )
        self._checked = True

    def _trainer_stub(self):
        if self._trainer is None:
            raise ValueError("no trainer address: pass trainer= or set LIGHTFARM_TRAINER")
        return self._trainer

    # ------------------------------------------------------------------ jobs

    def server_info(self):
        """The coordinator's ServerInfo (protocol and server version)."""
        self._check_protocol()
        return self._jobs.GetServerInfo(self._jobs_pb.ServerInfoRequest(), metadata=self._metadata)

    def submit(self, spec: Union[str, os.PathLike, dict], priority: int = 0):
        """Submits a dataset spec: a TOML file's path, or the spec as a dict (the TOML
        document's tables as dicts). Returns the Job."""
        if isinstance(spec, dict):
            req = self._jobs_pb.SubmitDatasetRequest(json=json.dumps(spec), priority=priority)
        else:
            path = Path(spec)
            try:
                text = path.read_text()
            except OSError as e:
                raise FileNotFoundError(f"reading {path}: {e.strerror}") from None
            req = self._jobs_pb.SubmitDatasetRequest(toml=text, priority=priority)
        return self._call(self._jobs.SubmitDataset, req)

    def job(self, job_id: str):
        return self._call(self._jobs.GetJob, self._jobs_pb.JobRef(job_id=job_id))

    def jobs(self) -> list:
        return list(self._call(self._jobs.ListJobs, self._jobs_pb.ListJobsRequest()).jobs)

    def watch(self, job_id: str) -> Iterator:
        """The job now, then again on every change, until it ends (a Job message each)."""
        self._check_protocol()
        try:
            for job in self._jobs.WatchJob(
                self._jobs_pb.JobRef(job_id=job_id), metadata=self._metadata
            ):
                yield job
        except grpc.RpcError as e:
            raise errors.from_rpc(e, self.address) from None

    def cancel(self, job_id: str):
        return self._call(self._jobs.CancelJob, self._jobs_pb.JobRef(job_id=job_id))

    def pause(self, job_id: str):
        return self._call(self._jobs.PauseJob, self._jobs_pb.JobRef(job_id=job_id))

    def resume(self, job_id: str):
        return self._call(self._jobs.ResumeJob, self._jobs_pb.JobRef(job_id=job_id))

    def wait(self, job_id: str, timeout: Optional[float] = None):
        """Watches the job until it ends; returns its last state."""
        started, last = time.monotonic(), None
        for last in self.watch(job_id):
            if finished(last):
                return last
            if timeout is not None and time.monotonic() - started > timeout:
                raise TimeoutError(f"job {job_id} still {job_state(last)} after {timeout} s")
        return last if last is not None else self.job(job_id)

    # ------------------------------------------------------------------ samples

    def samples(self, job_id: str, split: str = "") -> List:
        """The committed samples' records (SampleInfo) of a job, in index order."""
        out, offset = [], 0
        while True:
            page = self._call(
                self._samples.ListSamples,
                self._samples_pb.ListSamplesRequest(
                    job_id=job_id, split=split, offset=offset, limit=1000
                ),
            )
            out.extend(page.samples)
            offset += len(page.samples)
            if not page.samples or offset >= page.total:
                return out

    def get_sample(self, job_id: str, index: int):
        """(SampleInfo, EXR bytes) of one committed sample."""
        self._check_protocol()
        info, data = None, bytearray()
        try:
            for chunk in self._samples.GetSample(
                self._samples_pb.GetSampleRequest(job_id=job_id, index=index),
                metadata=self._metadata,
            ):
                if chunk.HasField("info"):
                    info = chunk.info
                else:
                    data.extend(chunk.data)
        except grpc.RpcError as e:
            raise errors.from_rpc(e, self.address) from None
        return info, bytes(data)

    def _stream(self, job_id: str, split: str, cursor: int, follow: bool, metadata_only: bool = False):
        """Raw StreamSamples: (SampleInfo, bytes) pairs in commit order from `cursor`."""
        self._check_protocol()
        req = self._samples_pb.StreamSamplesRequest(
            job_id=job_id, split=split, cursor=cursor, follow=follow, metadata_only=metadata_only
        )
        info, data = None, bytearray()
        for chunk in self._samples.StreamSamples(req, metadata=self._metadata):
            if chunk.HasField("info"):
                if info is not None:
                    yield info, bytes(data)
                info, data = chunk.info, bytearray()
            else:
                data.extend(chunk.data)
        if info is not None:
            yield info, bytes(data)

    # ------------------------------------------------------------------ trainer

    def submit_train(
        self,
        dataset: str,
        config: Union[None, str, os.PathLike, dict] = None,
        steps: int = 0,
        batch: int = 0,
        split: str = "",
    ):
        """Submits a train job to the trainer: `dataset` is a folder export under its
        --datasets or a `farm://HOST:PORT/JOB` address; `config` a train.toml path or TOML text
        as a dict of its keys (without dataset and out). Returns the TrainJob."""
        if config is None:
            text = ""
        elif isinstance(config, dict):
            text = _toml(config)
        else:
            text = Path(config).read_text()
        req = self._trainer_pb.SubmitTrainJobRequest(
            config_toml=text, dataset=dataset, steps=steps, batch=batch, split=split
        )
        return self._call(self._trainer_stub().SubmitTrainJob, req, service="trainer")

    def train_jobs(self) -> list:
        return list(
            self._call(
                self._trainer_stub().ListTrainJobs,
                self._trainer_pb.ListTrainJobsRequest(),
                service="trainer",
            ).jobs
        )

    def relight(
        self,
        job_id: str,
        image: Union[bytes, str, os.PathLike],
        hdri: Union[str, bytes],
        rotation_deg: float = 0.0,
        flip: bool = False,
        mask: Optional[bytes] = None,
        no_matte: bool = False,
    ):
        """Relights an image (PNG/JPEG/EXR bytes or path) with the newest checkpoint of train
        job `job_id` under `hdri` (an HDRI id of the trainer's catalog, or .hdr/.exr bytes).
        Returns the RelightResponse (relit_png and the intermediates as PNG bytes)."""
        if not isinstance(image, bytes):
            image = Path(image).read_bytes()
        kw = {"hdri_file": hdri} if isinstance(hdri, bytes) else {"hdri_id": hdri}
        req = self._trainer_pb.RelightRequest(
            job_id=job_id, image=image, mask=mask or b"", rotation_deg=rotation_deg,
            flip=flip, no_matte=no_matte, **kw,
        )
        return self._call(self._trainer_stub().Relight, req, service="trainer", timeout=600.0)


def _toml(d: dict, prefix: str = "") -> str:
    """A flat TOML rendering of a dict of scalars, lists and tables (train.toml's shape)."""
    lines, tables = [], []
    for k, v in d.items():
        if isinstance(v, dict):
            tables.append((k, v))
        else:
            lines.append(f"{k} = {json.dumps(v)}")
    out = "\n".join(lines) + "\n"
    for k, v in tables:
        name = f"{prefix}{k}"
        out += f"[{name}]\n" + _toml(v, prefix=f"{name}.")
    return out
