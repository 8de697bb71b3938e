"""Checks of the client that need no farm (run by tests/python_client.rs, or
`python -m unittest discover clients/python/tests`)."""

import unittest

import grpc

import lightfarm
from lightfarm import errors
from lightfarm.client import _channel, _toml
from lightfarm.sample import check_passes


class FakeRpcError(grpc.RpcError):
    def __init__(self, code, details):
        self._code, self._details = code, details

    def code(self):
        return self._code

    def details(self):
        return self._details


class Offline(unittest.TestCase):
    def test_errors_carry_the_servers_words(self):
        e = errors.from_rpc(FakeRpcError(grpc.StatusCode.NOT_FOUND, "unknown job `x`"), "http://h:1")
        self.assertIsInstance(e, lightfarm.NotFound)
        self.assertEqual(str(e), "unknown job `x`")
        e = errors.from_rpc(FakeRpcError(grpc.StatusCode.UNAVAILABLE, "refused"), "http://h:1")
        self.assertIsInstance(e, lightfarm.Unavailable)
        self.assertIn("cannot reach the coordinator at http://h:1 (refused)", str(e))

    def test_bad_inputs_are_named(self):
        with self.assertRaisesRegex(ValueError, "unknown pass 'depth'"):
            check_passes(["lit0", "depth"])
        with self.assertRaisesRegex(ValueError, "not like http://host:7070"):
            _channel("http://a/b", None)
        with self.assertRaisesRegex(ValueError, "bearer token is required"):
            lightfarm.Client("http://127.0.0.1:1", token="")
        with self.assertRaisesRegex(ValueError, "not a readable OpenEXR"):
            lightfarm.decode_exr(b"not an exr", name="bytes")
        with self.assertRaisesRegex(FileNotFoundError, "no manifest.jsonl"):
            list(lightfarm.read_folder("/nonexistent"))

    def test_another_protocol_version_is_refused_before_any_call(self):
        from lightfarm.v1 import jobs_pb2

        class Jobs:
            def GetServerInfo(self, req, metadata=None, timeout=None):
                return jobs_pb2.ServerInfo(protocol_version=99, server_version="9.9.9")

            def ListJobs(self, req, metadata=None, timeout=None):
                raise AssertionError("called past a protocol mismatch")

        client = lightfarm.Client("http://127.0.0.1:1", token="t")
        client._jobs = Jobs()
        with self.assertRaisesRegex(lightfarm.ProtocolMismatch, "protocol version 99, this client version 1"):
            client.jobs()

    def test_training_needs_a_trainer_address(self):
        client = lightfarm.Client("http://127.0.0.1:1", token="t", trainer=None)
        if client.trainer_address:
            self.skipTest("LIGHTFARM_TRAINER is set")
        with self.assertRaisesRegex(ValueError, "no trainer address"):
            client.submit_train("dataset")

    def test_train_configs_render_as_toml(self):
        text = _toml({"crop": 16, "split": "all", "net": {"widths": [8, 16]}})
        self.assertEqual(text, 'crop = 16\nsplit = "all"\n[net]\nwidths = [8, 16]\n')

    def test_shards_cover_every_index_once(self):
        try:
            from lightfarm.torch import shard_of
        except ImportError:
            self.skipTest("no torch")
        seen = sorted(i for shard in range(4) for i in range(103) if shard_of(i, 4) == shard)
        self.assertEqual(seen, list(range(103)))


if __name__ == "__main__":
    unittest.main()
