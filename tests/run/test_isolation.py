"""Another user of the machine cannot get in: fdbench's local Dask cluster refuses every client
but fdbench's own and serves no HTTP, and no child Python that fdbench starts (the OpenSim import
and peer processes, the Dask workers, multiprocessing's resource tracker) imports a module planted
in the folder it is run from.

The clusters are started as fdbench starts them (``DaskBackend``) and attacked as another user
would: a plain ``Client`` to the scheduler's address, a client with a certificate of its own, a TLS
connection without one, an HTTP request to every port the cluster listens on. Every cluster and
process is stopped in a ``finally``; traffic stays on 127.0.0.1."""

from __future__ import annotations

import importlib.util
import os
import socket
import ssl
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from typer.testing import CliRunner

from helpers.paths import ROOT
from fdbench.cli import app

ARM26 = ROOT / "examples" / "opensim" / "arm26.osim"
# modules that a child Python imports early (its bootstrap, multiprocessing's, fdbench's) and
# fdbench itself: each planted copy leaves a file 'imported-<name>' beside it when imported
PLANTED = ("json", "base64", "pickle", "socket", "selectors", "runpy", "subprocess", "fdbench")
MARK = ("import os\nopen(os.path.join(os.path.dirname(os.path.abspath(__file__)), 'imported-' + __name__), 'w')"
        ".close()\n")


def _needs_dask():
    pytest.importorskip("distributed", reason="Dask distributed is not installed (pip install '.[dask]')")
    pytest.importorskip("cryptography", reason="cryptography is not installed (pip install '.[dask]')")


def _needs_opensim():
    if importlib.util.find_spec("opensim") is None:
        pytest.skip("OpenSim is not installed (pip install '.[opensim]')")


def planted_folder(folder: Path) -> Path:
    """``folder`` with a planted copy of each module of PLANTED (fdbench as a package)."""
    folder.mkdir(exist_ok=True)
    for name in PLANTED:
        if name == "fdbench":
            (folder / name).mkdir()
            (folder / name / "__init__.py").write_text(MARK)
        else:
            (folder / f"{name}.py").write_text(MARK)
    return folder


def imported(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob("imported-*"))


@contextmanager
def local_cluster(workers: int = 1):
    """fdbench's local Dask cluster, started as ``report --backend dask --jobs N`` starts it."""
    from fdbench.execution import make_backend

    backend = make_backend("dask", jobs=workers)
    try:
        backend.start(workers)
        yield backend
    finally:
        backend.stop()


def _listening(pids) -> set[tuple[str, int]]:
    import psutil

    found = set()
    for pid in pids:
        try:
            process = psutil.Process(pid)
            connections = getattr(process, "net_connections", None) or process.connections  # psutil < 6
            connections = connections("inet")
        except psutil.NoSuchProcess:
            continue
        found |= {(c.laddr.ip, c.laddr.port) for c in connections if c.status == psutil.CONN_LISTEN}
    return found


def _process_tree() -> list[int]:
    import psutil

    me = psutil.Process()
    return [me.pid] + [child.pid for child in me.children(recursive=True)]


def _refuses_tls_without_certificate(host: str, port: int) -> bool:
    """True if the TLS server at host:port ends the connection of a client that offers no
    certificate (and checks none) before answering anything."""
    anyone = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    anyone.check_hostname, anyone.verify_mode = False, ssl.CERT_NONE
    with socket.create_connection((host, port), timeout=30) as raw:
        try:
            with anyone.wrap_socket(raw) as tls:
                tls.sendall(b"\x00" * 8)
                return tls.recv(1) == b""
        except TimeoutError:  # silent, but open: not a refusal
            return False
        except OSError:  # the handshake failed, or the server's alert (certificate required) came
            return True


def _http_answer(host: str, port: int) -> bytes:
    """What the server at host:port answers to an HTTP request for the scheduler's identity."""
    with socket.create_connection((host, port), timeout=30) as connection:
        connection.sendall(b"GET /json/identity.json HTTP/1.0\r\nHost: localhost\r\n\r\n")
        try:
            return connection.recv(100)
        except OSError:  # reset: the server closed on the bytes it could not take
            return b""


ATTACK = """
import sys
from distributed import Client
from distributed.security import Security

address, marker = sys.argv[1], sys.argv[2]
def f():
    open(marker, "w").close()
attempts = {"plain": (address, None), "tcp": ("tcp://" + address.split("://")[1], None),
            "own certificate": (address, Security.temporary())}
for what, (target, security) in attempts.items():
    try:
        client = Client(target, security=security, timeout="10s")  # 10 s bounds its retries
    except Exception as exc:
        print(what, "refused", type(exc).__name__)
    else:
        client.submit(f).result()
        print(what, "connected")
"""


def test_another_user_s_client_cannot_submit_to_the_local_cluster_and_no_http_is_served(tmp_path):
    _needs_dask()
    import subprocess

    before = _listening(_process_tree())
    marker = tmp_path / "ran"
    with local_cluster(workers=1) as backend:
        address = backend.client.scheduler.address
        assert address.startswith("tls://127.0.0.1:")
        # the attack, from another process that knows the address: Client(addr).submit(f)
        done = subprocess.run([sys.executable, "-c", ATTACK, address, str(marker)], capture_output=True, text=True,
                              timeout=120, cwd=tmp_path)
        outcomes = [line.split(" refused ")[0] for line in done.stdout.splitlines() if " refused " in line]
        assert outcomes == ["plain", "tcp", "own certificate"], done.stdout + done.stderr
        assert not marker.exists()
        # fdbench's own client does reach it: the address is the cluster's
        assert backend.client.submit(os.getpid, pure=False).result(timeout=60) != os.getpid()
        ports = _listening(_process_tree()) - before
        (worker, info), = backend.client.scheduler_info()["workers"].items()
        comms = {address, worker, info["nanny"]}  # the TLS comms of the scheduler, the worker and its nanny
        assert ports == {(h, int(p)) for h, p in (a[len("tls://"):].rsplit(":", 1) for a in comms)}
        for ip, number in ports:
            assert not _http_answer(ip, number).startswith(b"HTTP/"), f"port {number} serves HTTP"
            assert _refuses_tls_without_certificate(ip, number), f"port {number} talks to a client without certificate"
    assert not any(Path(p).name.startswith("fdbench-dask-") or "dask-scratch-space" in p for p in sys.path)


LOCAL_CLUSTER = """
import json, os, sys
from fdbench.execution import make_backend

if __name__ == "__main__":
    backend = make_backend("dask", jobs=1)
    backend.start(1)
    try:
        paths = backend.client.run(lambda: list(sys.path))
    finally:
        backend.stop()
    print(json.dumps({"paths": list(paths.values()), "safe_path": os.environ.get("PYTHONSAFEPATH")}))
"""


def test_a_module_planted_in_the_current_folder_is_not_imported_by_the_dask_cluster_s_processes(tmp_path):
    """fdbench started in a shared folder (a fresh process run as the ``fdbench`` script runs:
    its own path starts with the script's folder, not the current one) starts its local cluster:
    neither the worker processes nor multiprocessing's resource tracker import the planted modules."""
    _needs_dask()
    if sys.version_info < (3, 11):
        pytest.skip("Python 3.10 has no safe-path mode for the workers' start (PYTHONSAFEPATH)")
    import json
    import subprocess

    from helpers.processes import python_path

    folder = planted_folder(tmp_path / "shared")
    script = tmp_path / "bin" / "cluster.py"
    script.parent.mkdir()
    script.write_text(LOCAL_CLUSTER)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONSAFEPATH"}
    env["PYTHONPATH"] = python_path(ROOT)  # this fdbench
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=folder,
                          env=env)
    assert done.returncode == 0, done.stderr
    assert imported(folder) == []
    answer = json.loads(done.stdout.splitlines()[-1])
    for path in answer["paths"]:
        assert "" not in path and str(folder) not in path
    assert answer["safe_path"] is None  # set for the cluster's processes only: the command's own is as it was


def test_before_python_3_11_a_local_cluster_is_refused_in_a_folder_that_others_can_write(tmp_path, monkeypatch):
    """Without PYTHONSAFEPATH (Python 3.10) the cluster's processes would import from the current
    folder: a local cluster is then refused in a folder another user can write to, in one line."""
    _needs_dask()
    import fdbench.execution as execution

    monkeypatch.setattr(execution, "SAFE_PATH", False)
    shared, own = tmp_path / "shared", tmp_path / "own"
    shared.mkdir()
    shared.chmod(0o1777)  # as /tmp
    own.mkdir(mode=0o700)
    monkeypatch.chdir(shared)
    db = shared / "runs.sqlite"
    result = CliRunner().invoke(app, ["report", "--torque", "cs", "--seeds", "1", "--backend", "dask",
                                      "--db", str(db), "-q"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "writable by other users" in lines[0] and "Python >= 3.11" in lines[0], lines
    assert not db.exists()
    monkeypatch.chdir(own)
    execution.make_backend("dask", jobs=1)  # checked: a folder of one's own is fine


def test_a_module_planted_in_the_current_folder_is_not_imported_by_the_opensim_children(tmp_path, monkeypatch):
    _needs_opensim()
    folder = planted_folder(tmp_path / "shared")
    # the case: 'fdbench models show arm26.osim' in a shared folder (content of its own: no cache)
    (folder / "arm26.osim").write_bytes(ARM26.read_bytes() + f"<!-- {tmp_path} -->\n".encode())
    monkeypatch.chdir(folder)
    result = CliRunner().invoke(app, ["models", "show", "arm26.osim"])
    assert result.exit_code == 0, result.output
    assert "r_shoulder_elev" in result.stdout  # OpenSim's child did read the model
    from fdbench.peers.child import opensim_version

    assert opensim_version().startswith("4.")
    assert imported(folder) == []
    assert sorted(p.name for p in folder.iterdir()) == sorted(["arm26.osim", *(
        n if n == "fdbench" else f"{n}.py" for n in PLANTED)])  # and the children wrote nothing there


def test_the_children_still_import_what_this_process_imports(tmp_path, monkeypatch):
    """Isolated children ignore PYTHONPATH: they get this process's path instead (an OpenSim found
    through PYTHONPATH, plugins, this fdbench)."""
    import subprocess

    from fdbench.isolation import python_command

    extra = tmp_path / "on-path"
    extra.mkdir()
    (extra / "only_here.py").write_text("WHERE = __file__\n")
    monkeypatch.syspath_prepend(str(extra))
    monkeypatch.chdir(planted_folder(tmp_path / "shared"))
    code = "import only_here, fdbench, sys; print(only_here.WHERE); print(fdbench.__file__); print(sys.flags.isolated)"
    done = subprocess.run(python_command(code), capture_output=True, text=True, timeout=120, cwd=tmp_path / "shared")
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [str(extra / "only_here.py"), str(Path(sys.modules["fdbench"].__file__)), "1"]
    assert imported(tmp_path / "shared") == []


def test_a_tls_scheduler_without_the_client_s_files_is_refused_in_one_line(tmp_path, monkeypatch):
    _needs_dask()
    for name in ("CA_FILE", "CLIENT__CERT", "CLIENT__KEY"):
        monkeypatch.delenv("DASK_DISTRIBUTED__COMM__TLS__" + name, raising=False)
    db = tmp_path / "never.sqlite"
    result = CliRunner().invoke(app, ["report", "--torque", "cs", "--seeds", "1", "--backend", "dask",
                                      "--scheduler", "tls://127.0.0.1:1", "--db", str(db), "-q"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "DASK_DISTRIBUTED__COMM__TLS__CA_FILE" in lines[0], lines
    assert not db.exists()


def test_a_tls_scheduler_is_reached_with_the_files_of_dask_s_configuration(tmp_path):
    """A scheduler and a worker started with TLS as the README shows; fdbench connects with the
    client's files given by Dask's configuration, and a wrong CA is refused in one line."""
    _needs_dask()
    import dask
    from distributed.security import Security

    from fdbench.execution import BackendError, DaskBackend
    from helpers.processes import scheduler_address, start_in_session, stop_session

    ours, theirs = Security.temporary(), Security.temporary()
    files = {}
    for name, text in (("ca.pem", ours.tls_ca_file), ("key.pem", ours.tls_client_key),
                       ("other-ca.pem", theirs.tls_ca_file)):
        files[name] = tmp_path / name
        files[name].write_text(text)
    tls = ["--tls-ca-file", files["ca.pem"], "--tls-cert", files["ca.pem"], "--tls-key", files["key.pem"]]
    procs = []
    try:
        log = tmp_path / "scheduler.log"
        procs.append(start_in_session([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                             "--port", "0", "--no-dashboard", *tls], log, tmp_path))
        address = scheduler_address(procs[0], log)
        assert address.startswith("tls://127.0.0.1:")
        procs.append(start_in_session([sys.executable, "-m", "distributed.cli.dask_worker", address, "--host", "127.0.0.1",
                             "--nthreads", "1", "--no-dashboard", "--local-directory", tmp_path / "w", *tls],
                            tmp_path / "worker.log", tmp_path))
        client_files = {"distributed.comm.tls.ca-file": str(files["ca.pem"]),
                        "distributed.comm.tls.client.cert": str(files["ca.pem"]),
                        "distributed.comm.tls.client.key": str(files["key.pem"])}
        with dask.config.set(client_files):
            backend = DaskBackend(scheduler=address)
            backend.check()
            try:
                backend.start(1)
                assert backend.client.submit(os.getpid, pure=False).result(timeout=60) != os.getpid()
                assert backend.workers == 1
            finally:
                backend.stop()
        with dask.config.set(dict(client_files, **{"distributed.comm.tls.ca-file": str(files["other-ca.pem"])})):
            backend = DaskBackend(scheduler=address)
            backend.check()
            with pytest.raises(BackendError, match="TLS handshake"):
                backend.connect()
    finally:
        for proc in reversed(procs):
            stop_session(proc)
