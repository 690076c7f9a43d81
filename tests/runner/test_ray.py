"""The Ray backend runs the same trials as the local pool and writes the same results.csv."""

import csv

import pytest
import ray

from polar_sim.runner import run_experiment
from polar_sim.runner.backends import grpc_status

TIMING = {"elapsed_s"}


def _rows(path):
    with open(path, newline="") as fh:
        return {r["trial_key"]: r for r in csv.DictReader(fh)}


# A local Ray instance with 2 CPUs and the local 2-worker pool give results.csv files that are
# equal trial for trial: every metric bit-identical (the CSV holds repr floats), timing excluded.
def test_ray_results_equal_local_pool(tmp_path):
    over = {"scene": ["office2d", "rover_flat"], "seed": [0, 1]}
    try:
        a = run_experiment("sensors", quick=True, split="dev", out=tmp_path / "a", workers=2, progress=False,
                           overrides=over)
        b = run_experiment("sensors", quick=True, split="dev", out=tmp_path / "b", backend="ray", workers=2,
                           progress=False, overrides=over)
        # the address probe gets a gRPC answer (status 200) from a real cluster's control service
        host, port = ray.get_runtime_context().gcs_address.rsplit(":", 1)
        assert grpc_status(host, int(port)) == 200
    finally:
        ray.shutdown()
    assert a.passed and b.passed and len(b.table) == 4
    ra, rb = _rows(tmp_path / "a" / "results.csv"), _rows(tmp_path / "b" / "results.csv")
    assert ra.keys() == rb.keys()
    for key in ra:
        assert {k: v for k, v in ra[key].items() if k not in TIMING} == \
               {k: v for k, v in rb[key].items() if k not in TIMING}


# An address where no cluster listens is a clear error within seconds, not a hang.
def test_unreachable_address(tmp_path):
    with pytest.raises(ValueError, match="cannot reach the Ray cluster"):
        run_experiment("sensors", quick=True, split="dev", backend="ray", address="127.0.0.1:1", progress=False,
                       out=tmp_path / "a")
    with pytest.raises(ValueError, match="HOST:PORT"):
        run_experiment("sensors", quick=True, split="dev", backend="ray", address="nonsense", progress=False)
    assert not (tmp_path / "a").exists()


# An address where something else answers (a web server, a proxy: a TCP connection succeeds) is
# one line naming the address, from the probe, before ray.init (which would retry for minutes,
# a warning a second); the run folder is not created.
@pytest.mark.parametrize("reply, says", [
    (b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\n\r\n", "does not answer gRPC"),
    # an HTTP/2 server: SETTINGS, then HEADERS on stream 1 with :status 404 (static index 13)
    (b"\x00\x00\x00\x04\x00\x00\x00\x00\x00" + b"\x00\x00\x01\x01\x04\x00\x00\x00\x01\x8d", "status 404"),
])
def test_address_of_something_that_is_not_ray(tmp_path, reply, says):
    import socket
    import threading

    srv = socket.create_server(("127.0.0.1", 0))
    stop = threading.Event()

    def serve():
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            conn.recv(4096)
            conn.sendall(reply)
            conn.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    address = f"127.0.0.1:{srv.getsockname()[1]}"
    try:
        with pytest.raises(ValueError, match=rf"address: what listens at '{address}' .*{says}") as e:
            run_experiment("sensors", quick=True, split="dev", backend="ray", address=address, progress=False,
                           out=tmp_path / "b")
    finally:
        stop.set()
        t.join()
        srv.close()
    assert "\n" not in str(e.value) and not (tmp_path / "b").exists() and not ray.is_initialized()


# The probe's HPACK integers follow RFC 7541's examples (C.1.1, C.1.2), so header values of any
# length (a long host name in :authority) are encoded right.
def test_probe_hpack_integers():
    from polar_sim.runner.backends import _h2_literal, _hpack_int

    assert _hpack_int(10, 5) == bytes([10]) and _hpack_int(1337, 5) == bytes([31, 154, 10])
    assert _h2_literal(31, "application/grpc")[:2] == bytes([15, 16])
    assert _h2_literal(1, "h" * 200)[:3] == bytes([1, 127, 73])
