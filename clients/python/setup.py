"""Builds the package with its gRPC stubs generated from the repository's proto/ directory
(never copied by hand): `lightfarm/v1/*_pb2.py` and `*_pb2_grpc.py` in the built package."""

import os
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


def proto_root() -> Path:
    here = Path(__file__).resolve().parent
    root = Path(os.environ.get("LIGHTFARM_PROTO", here.parent.parent / "proto"))
    if not (root / "lightfarm" / "v1" / "jobs.proto").is_file():
        raise SystemExit(
            f"lightfarm: no proto/lightfarm/v1/*.proto under {root}; build from the lightfarm "
            "repository (pip install ./clients/python) or set LIGHTFARM_PROTO"
        )
    return root


class BuildWithStubs(build_py):
    def run(self):
        super().run()
        from grpc_tools import protoc
        import grpc_tools

        root = proto_root()
        out = Path(self.build_lib)
        files = sorted(str(p) for p in (root / "lightfarm" / "v1").glob("*.proto"))
        well_known = Path(grpc_tools.__file__).parent / "_proto"
        args = [
            "grpc_tools.protoc",
            f"-I{root}",
            f"-I{well_known}",
            f"--python_out={out}",
            f"--grpc_python_out={out}",
            *files,
        ]
        if protoc.main(args) != 0:
            raise SystemExit(f"lightfarm: protoc failed on {root}")
        (out / "lightfarm" / "v1" / "__init__.py").write_text(
            '"""Generated from proto/lightfarm/v1 at build time."""\n'
        )


setup(cmdclass={"build_py": BuildWithStubs})
