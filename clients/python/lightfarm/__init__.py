"""Python client of a lightfarm render farm.

    client = lightfarm.Client("http://farm:7070", token)
    job = client.submit("examples/dataset.toml")
    for sample in lightfarm.SampleStream(client, job.id, split="train"):
        sample["lit0"], sample["normal"], sample.metadata["sample"]["lighting"]
"""

import os as _os

# DataLoader workers are forked processes that open their own channels; gRPC allows that only
# with its fork support on, which must be set before grpc is first imported.
_os.environ.setdefault("GRPC_ENABLE_FORK_SUPPORT", "true")

from ._protocol import PROTOCOL_VERSION  # noqa: E402
from .client import Client, finished, job_state
from .errors import (
    Conflict,
    InvalidArgument,
    LightfarmError,
    NotFound,
    ProtocolMismatch,
    Unauthenticated,
    Unavailable,
)
from .export import read_folder, read_webdataset
from .sample import PASSES, Sample, decode_exr
from .stream import SampleStream

__version__ = "0.1.0"

__all__ = [
    "PROTOCOL_VERSION", "PASSES", "Client", "SampleStream", "Sample", "decode_exr",
    "read_folder", "read_webdataset", "finished", "job_state", "LightfarmError",
    "Unauthenticated", "NotFound", "InvalidArgument", "Conflict", "Unavailable",
    "ProtocolMismatch",
]
