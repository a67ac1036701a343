"""A Dask scheduler that cannot be used: malformed addresses are refused before any client exists, and a server
that accepts TCP but does not speak Dask is given up after the timeout.

No cluster is started: the failures need none. The command-line cases run in a subprocess so that what the
interpreter prints while shutting down (a ``Client.__del__`` traceback) is on the stderr the tests read.
"""

import json
import os
import socket
import subprocess
import sys
import threading
import time

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth.batch.distributed as dist
from conftest import REPO, make_scene

MALFORMED = ["", "tcp://[::1", "inproc://x", "foo://10.0.0.5:8786", "tcp://10.0.0.5", "tcp://10.0.0.5:99999",
             "tcp://10.0.0.5:port", "tcp://10.0.0.5:²", "tcp://10.0.0.5:8786/path", " tcp://10.0.0.5:8786",
             "tcp://::1:8786"]


@pytest.fixture
def no_client(monkeypatch):
    """dask.distributed replaced by a module whose Client fails the test: nothing may get that far."""
    class Refused:
        def __init__(self, *args, **kwargs):
            raise AssertionError(f"a Client was created for {args!r}")

    class FakeDistributed:
        Client = Refused

    monkeypatch.setattr(dist, "_import_distributed", lambda: FakeDistributed)
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)


@pytest.mark.parametrize("address", MALFORMED)
def test_a_malformed_address_is_one_value_error_before_any_client(no_client, address):
    with pytest.raises(ValueError, match="scheduler address") as info:
        dist.connect(address, timeout=1)
    assert repr(address) in str(info.value) and "tcp://" in str(info.value)  # what arrived, and the fix


def test_a_malformed_address_from_the_environment_names_the_variable(no_client, monkeypatch):
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://[::1")
    with pytest.raises(ValueError, match="DASK_SCHEDULER_ADDRESS 'tcp://\\[::1'"):
        dist.connect(timeout=1)


def test_a_bad_scheduler_file_names_the_file(no_client, tmp_path):
    cases = {"json.json": "{not json", "list.json": json.dumps(["tcp://10.0.0.5:8786"]),
             "address.json": json.dumps({"address": "inproc://x"}), "number.json": json.dumps({"address": 8786})}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(ValueError, match="scheduler file") as info:
            dist.connect(scheduler_file=tmp_path / name, timeout=1)
        assert name in str(info.value)


def test_well_formed_addresses_are_accepted():
    for address in ("tcp://10.0.0.5:8786", "10.0.0.5:8786", "tcp://[::1]:8786", "tls://scheduler.example.org:8786",
                    "ws://node-3:8786", "tcp://my_host.local:1"):
        assert dist.scheduler_address(address) == address


# ----------------------------------------------------------------------------- the command line, in a subprocess
distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed: "
                                  "pip install -e '.[test,distributed]' (CI installs it)")

_CHILD = r"""
import json, os, sys
from sparsedepth.complete import main

cases = json.loads(sys.argv[1])
codes = []
for extra, env in cases:
    os.environ.pop("DASK_SCHEDULER_ADDRESS", None)
    os.environ.update(env)
    codes.append(main(extra))
    sys.stderr.flush()
print(json.dumps(codes))
"""


def _frames(folder):
    folder.mkdir()
    image, depth = make_scene((12, 16))
    iio.imwrite(folder / "rgb_00.png", image)
    np.save(folder / "depth_00.npy", depth)
    return folder


def _run_cli(cases, tmp_path, timeout=60):
    """Every case through main() in one child process; its exit codes and its whole stderr."""
    common = ["--batch", str(_frames(tmp_path / "frames")), "--keep-fraction", "0.1", "-q"]
    cases = [([*common, "--csv", str(tmp_path / f"{i}.csv"), *extra], env) for i, (extra, env) in enumerate(cases)]
    env = {k: v for k, v in os.environ.items() if k != "DASK_SCHEDULER_ADDRESS"}
    env["OPENBLAS_NUM_THREADS"] = "1"
    try:
        out = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(cases)], cwd=REPO, capture_output=True,
                             text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        pytest.fail("the command line did not end: it waited for a scheduler that will never answer")
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


def test_cli_malformed_addresses_are_one_line_each_and_exit_2(tmp_path):
    (tmp_path / "bad.json").write_text(json.dumps({"address": "tcp://[::1"}))
    cases = [(["--scheduler", ""], {}), (["--scheduler", "tcp://[::1"], {}), (["--scheduler", "inproc://x"], {}),
             (["--scheduler-file", str(tmp_path / "bad.json")], {}), ([], {"DASK_SCHEDULER_ADDRESS": "tcp://[::1"})]
    codes, err = _run_cli(cases, tmp_path)
    assert codes == [2] * len(cases)
    lines = err.splitlines()
    assert len(lines) == len(cases), err  # one line each, and no traceback at shutdown
    for line, name in zip(lines, ["--scheduler", "--scheduler", "--scheduler", "--scheduler-file",
                                  "DASK_SCHEDULER_ADDRESS"]):
        assert line.startswith("python -m sparsedepth.complete: error:") and name in line, line
    assert not any((tmp_path / f"{i}.csv").exists() for i in range(len(cases)))


class _SilentServer:
    """A TCP server on 127.0.0.1 that accepts connections and never sends a byte (or sends ``greeting``)."""

    def __init__(self, greeting=b""):
        self.greeting = greeting
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.sock.settimeout(0.05)  # accept() wakes up to see stop()
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.accepted = []
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        while not self.stopped.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:  # socket.timeout included
                continue
            self.accepted.append(conn)
            if self.greeting:
                conn.sendall(self.greeting)

    def stop(self):
        self.stopped.set()
        self.thread.join(timeout=5)
        self.sock.close()
        for conn in self.accepted:
            conn.close()


@pytest.fixture
def silent_servers():
    servers = [_SilentServer(), _SilentServer(b"SSH-2.0-OpenSSH_9.6\r\n")]
    yield servers
    for server in servers:
        server.stop()


def test_cli_a_server_that_does_not_speak_dask_ends_after_the_timeout_with_exit_2(silent_servers, tmp_path):
    cases = [(["--scheduler", server.address, "--scheduler-timeout", "0.5"], {}) for server in silent_servers]
    start = time.monotonic()
    codes, err = _run_cli(cases, tmp_path)
    assert time.monotonic() - start < 60  # a hang guard only
    assert codes == [2, 2]
    lines = err.splitlines()
    assert len(lines) == 2, err
    for line, server in zip(lines, silent_servers):
        assert server.address in line and "no Dask scheduler answered" in line, line
    assert all(server.accepted for server in silent_servers)  # the connection was made: TCP alone is not enough
