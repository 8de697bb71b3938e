"""`SampleStream`: a job's committed samples as numpy arrays, in commit order, resumable from
a cursor, following a job that still renders, and surviving coordinator restarts."""

from __future__ import annotations

import time
from typing import Iterable, Iterator, Optional

import grpc

from . import errors
from .client import Client, finished
from .sample import Sample, check_passes


class SampleStream:
    """Iterates over the committed samples of `job` (of `split`: "train", "test" or "" for
    both) as `Sample`s holding `passes` (default: all six).

    The stream starts at `cursor` (0: the beginning) and `stream.cursor` is always where to
    resume after the samples yielded so far: a new `SampleStream(..., cursor=stream.cursor)`
    continues with no gap and no repeat. With `follow` (default) it waits for samples still
    to come and ends when the job has ended; without, it ends after what is committed now.
    When the coordinator goes away mid-stream it retries with backoff for `retry_seconds`
    before raising `errors.Unavailable`.
    """

    def __init__(
        self,
        client: Client,
        job: str,
        split: str = "train",
        passes: Optional[Iterable[str]] = None,
        cursor: int = 0,
        follow: bool = True,
        retry_seconds: float = 300.0,
        poll_seconds: float = 1.0,
    ):
        self.client = client
        self.job = job
        self.split = split
        self.passes = check_passes(passes)
        self.cursor = cursor
        self.follow = follow
        self.retry_seconds = retry_seconds
        self.poll_seconds = poll_seconds
        #: Outages waited out so far (calls that failed and were retried).
        self.retries = 0
        # Unknown jobs fail here, with the server's words, not at the first next().
        client.job(job)

    def __iter__(self) -> Iterator[Sample]:
        for info, data in self._records(metadata_only=False):
            yield Sample.from_record(info, data, self.passes)

    def infos(self) -> Iterator:
        """The same walk through the job with the records (SampleInfo) only, no EXRs."""
        for info, _ in self._records(metadata_only=True):
            yield info

    def _records(self, metadata_only: bool):
        """(SampleInfo, EXR bytes) from the cursor on, advancing it, following and retrying."""
        outage_since = None
        while True:
            try:
                got_any = False
                for info, data in self.client._stream(
                    self.job, self.split, self.cursor, False, metadata_only
                ):
                    got_any = True
                    outage_since = None
                    self.cursor = info.sequence + 1
                    yield info, data
                if got_any:
                    continue
                if not self.follow or finished(self.client.job(self.job)):
                    # Commits may land between the stream's end and the state check.
                    late = self.client._stream(self.job, self.split, self.cursor, False, True)
                    if next(late, None) is None:
                        return
                    continue
                time.sleep(self.poll_seconds)
            except grpc.RpcError as e:
                if e.code() not in errors.TRANSIENT:
                    raise errors.from_rpc(e, self.client.address) from None
                outage_since = self._wait_out(outage_since, e)
            except errors.Unavailable as e:
                outage_since = self._wait_out(outage_since, e)

    def _wait_out(self, since, e):
        self.retries += 1
        now = time.monotonic()
        since = since if since is not None else now
        if now - since > self.retry_seconds:
            if isinstance(e, errors.LightfarmError):
                raise e
            raise errors.from_rpc(e, self.client.address) from None
        time.sleep(min(2.0, 0.2 + (now - since) / 4))
        return since
