"""The `robocell` command as users and other programs use it: real subprocesses, or `main` with what it prints.

The commands that talk to a running cell are in test_cli_cell.py.
"""

import ast
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from robocell.core_cy.scoring import volumetric_iou
from robocell.core_cy.superquadric import Superquadric

from robocell.cli.jobs import format_status
from robocell.cli.main import build_parser, main
from robocell.wire.config import CellConfig, load_config
from robocell.wire.messages import CellStatus, DiskUsage, ReconstructorStatus

from tests.bundles import edit_scan
from tests.cell_fixtures import free_port, wait_until

BUNNY = Path(__file__).resolve().parents[2] / "shared" / "data" / "bunny"


def robocell(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "robocell", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def lines(process):
    return [json.loads(line) for line in process.stdout.splitlines()]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """One bundle of each family from `robocell sim`, with its truth."""
    out = tmp_path_factory.mktemp("sim")
    paths = []
    for shape in ("box", "cylinder", "ellipsoid", "rounded-box"):
        process = robocell("sim", "scans", "--out", out, "--shape", shape, "--seed", 11)
        assert process.returncode == 0, process.stderr
        paths += [Path(p) for p in process.stdout.split()]
    return paths


def test_simulated_scans_scored_against_the_truth(simulated):
    process = robocell("reconstruct", *simulated)
    assert process.returncode == 0, process.stderr
    results = lines(process)
    assert [r["scan"] for r in results] == [str(p) for p in simulated]  # one line each, in order
    for path, result in zip(simulated, results):
        truth = Superquadric.from_dict(json.loads((path / "truth.json").read_text()))
        fit = Superquadric.from_dict(result["superquadric"])
        assert volumetric_iou(fit, truth) > 0.75, path.name
        assert len(result["silhouette_iou"]) == 3 and min(result["silhouette_iou"]) > 0.85
        assert result["timings_ms"]["total"] > 0 and "points" not in result


def test_points_option_adds_the_cloud(simulated):
    (result,) = lines(robocell("reconstruct", "--points", "--n-points", 400, simulated[0]))
    points = np.asarray(result["points"])
    assert points.ndim == 2 and points.shape[1] == 3 and 300 < len(points) <= 400


def test_bunny_real_photographs():
    if not (BUNNY / "scan.json").exists():
        pytest.skip(f"no test data at {BUNNY}")
    (result,) = lines(robocell("reconstruct", BUNNY))
    assert np.mean(result["silhouette_iou"]) >= 0.7


def _broken(tmp_path, template, name, change):
    target = shutil.copytree(template, tmp_path / name)
    change(target)
    return target


BAD_BUNDLES = {
    "missing-scan-json": (lambda d: (d / "scan.json").unlink(), "no scan.json"),
    "missing-image": (lambda d: (d / "view1.jpg").unlink(), "view 1: image file 'view1.jpg' not found"),
    "truncated-jpeg": (lambda d: (d / "view2.jpg").write_bytes((d / "view2.jpg").read_bytes()[:3000]),
                       "view 2: the JPEG is truncated"),
    "garbage-jpeg": (lambda d: (d / "view0.jpg").write_bytes(b"\xff\xd8 this is not a JPEG \xff\xd9"),
                     "view 0: image file 'view0.jpg' is not a decodable image"),
    "empty-silhouette": (lambda d: edit_scan(d, lambda s: s.update(
        segmentation={"method": "hsv", "lower": [50, 90, 40], "upper": [70, 255, 255]})),
        "view 0: the silhouette is empty"),
    "silhouette-everywhere": (lambda d: edit_scan(d, lambda s: s.update(
        segmentation={"method": "threshold", "value": 0})), "touches all four image borders"),
    "one-view": (lambda d: edit_scan(d, lambda s: s.update(views=s["views"][:1])), "need at least 2 views"),
    "singular-pose": (lambda d: edit_scan(d, lambda s: s["views"][1].update(
        T_world_cam=[[0, 0, 0, 0.5], [0, 0, 0, 0], [0, 0, 0, 0.5], [0, 0, 0, 1]])), "view 1: T_world_cam"),
    "scaled-pose": (lambda d: edit_scan(d, lambda s: s["views"][2].update(
        T_world_cam=(np.diag([2.0, 2.0, 2.0, 1.0])).tolist())), "view 2: T_world_cam is not a rigid transform"),
    "nan-in-K": (lambda d: edit_scan(d, lambda s: s["views"][0]["K"][1].__setitem__(1, float("nan"))),
                 "view 0: K contains NaN"),
    "under-the-table": (lambda d: edit_scan(d, lambda s: s.update(support_plane=[0, 0, -1, 0])), "under the table"),
    "malformed-json": (lambda d: (d / "scan.json").write_text('{"views": ['), "scan.json is not valid JSON"),
}


def test_bad_bundles_fail_one_by_one(tmp_path, sphere_bundle_template):
    good = shutil.copytree(sphere_bundle_template, tmp_path / "good")
    bad = [_broken(tmp_path, sphere_bundle_template, name, change) for name, (change, _) in BAD_BUNDLES.items()]
    process = robocell("reconstruct", good, *bad, good)
    assert process.returncode == 1
    results = lines(process)
    assert len(results) == len(bad) + 2
    assert "superquadric" in results[0] and "superquadric" in results[-1]  # the others still finish
    for (name, (_, message)), result in zip(BAD_BUNDLES.items(), results[1:-1]):
        assert result["scan"] == str(tmp_path / name)
        assert message in result["error"], (name, result["error"])
        assert "\n" not in result["error"]
    assert all(str(tmp_path / name) in process.stderr for name in BAD_BUNDLES)  # said to a person too


# --- one way to build the command ----------------------------------------------------------------------

HEAVY = ("zenoh", "cv2", "scipy", "rerun", "httpx", "robocell.core_cy.reconstruct", "pydantic")


def test_the_parser_loads_nothing_heavy():
    """`robocell --help` and the parsing before every command load none of what the commands run."""
    probe = ("import sys; from robocell.cli.main import build_parser; build_parser(); "
             f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == []


def test_no_command_talks_http_itself():
    """The camera's HTTP errors are translated in one place, the Axis grabber: the command line uses it."""
    package = Path(__file__).resolve().parents[1] / "robocell"
    for path in sorted(package.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            assert not [n for n in names if n.split(".")[0] == "httpx"], path.name


@pytest.mark.parametrize("argv, refused", [
    (["sim", "camera", "--shape", "box"], "--shape box"),
    (["sim", "scans", "--protocol", "opc"], "--protocol opc"),
    (["sim", "kuka", "--out", "x"], "--out x"),
])
def test_each_simulator_takes_only_its_own_options(argv, refused, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2 and f"unrecognized arguments: {refused}" in capsys.readouterr().err


def test_the_global_options_go_before_or_after_the_command(tmp_path, capsys):
    path = tmp_path / "cell.toml"
    path.write_text('cell_id = "bay7"\n')
    for argv in (["--config", str(path), "config"], ["config", "--config", str(path)], ["config", "-v", "--config",
                                                                                          str(path)]):
        assert main(argv) == 0
        assert json.loads(capsys.readouterr().out)["cell_id"] == "bay7", argv
    # given on both sides, the one after the command wins; left out after it, the one before stays
    args = build_parser().parse_args(["--config", "a.toml", "-v", "jobs", "--config", "b.toml"])
    assert (args.config, args.verbose) == ("b.toml", True)


def test_the_printed_configuration_reads_back_as_the_same(tmp_path, capsys):
    """`robocell config > cell.json` is a file every --config reads, to the same configuration."""
    path = tmp_path / "cell.toml"
    path.write_text('cell_id = "bay7"\n[robot]\nbackend = "kuka"\n[robot.kuka]\nprotocol = "opc"\n'
                    'host = "192.0.2.20"\n[camera]\nbackend = "sim"\njpeg_quality = 70\n')
    assert main(["--config", str(path), "config"]) == 0
    printed = tmp_path / "printed.json"
    printed.write_text(capsys.readouterr().out)
    assert load_config(printed) == load_config(path) != CellConfig()


def test_a_wrong_poses_file_is_one_line(tmp_path, capsys):
    """Checked before anything is sent: no router, no cell needed."""
    wrong = {"one-pose.json": ([[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0.3], [0, 0, 0, 1]],
                               "expected a JSON list of 2 to 16 4x4 flange poses (flange-to-base, metres), "
                               "got an array of shape (4, 4)"),
                 "three-by-three.json": ([np.eye(3).tolist()] * 4, "got an array of shape (4, 3, 3)"),
                 "not-rigid.json": ([(2 * np.eye(4)).tolist()] * 16, "flange_poses.0: Value error, pose "),
                 "not-json.json": ("[[1, 0", "not JSON")}
    for name, (poses, message) in wrong.items():
        (tmp_path / name).write_text(poses if isinstance(poses, str) else json.dumps(poses))
        assert main(["scan", "--poses", str(tmp_path / name)]) == 2, name
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and err.startswith(f"robocell scan: {tmp_path / name}: "), err
        assert message in err, (name, err)
    main(["scan", "--poses", str(tmp_path / "not-rigid.json")])
    assert "(and 15 more)" in capsys.readouterr().err


def test_an_unreachable_router_is_one_line_without_zenoh_source_paths(tmp_path, capsys):
    path, port = tmp_path / "cell.toml", free_port()
    path.write_text(f'[zenoh]\nrouter = "tcp/127.0.0.1:{port}"\n')
    assert main(["jobs", "--config", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"robocell jobs: cannot reach the Zenoh router at tcp/127.0.0.1:{port}: ")
    assert err.count("\n") == 1 and ".rs" not in err and "cargo" not in err


def test_status_columns_line_up_with_their_headers():
    workers = [ReconstructorStatus(worker="lab-gpu-host-with-a-long-name.r0_123456", capacity=12, in_flight=3,
                                   in_flight_here=1, healthy=False, heartbeat_age_s=None, sent=1234, failed=5),
               ReconstructorStatus(worker="r1", capacity=1, in_flight=0, in_flight_here=0, healthy=True,
                                   heartbeat_age_s=0.25, sent=7, failed=0)]
    status = CellStatus(cell="bay", started=0.0, time=30.0, workers={"robot": True, "camera": False},
                        reconstructors=workers, queued=0, max_queued=100, waiting_for_reconstructor=0,
                        jobs={"succeeded": 3}, recent_failures=[])
    lines = format_status(status).splitlines()
    header = next(i for i, line in enumerate(lines) if line.split()[:1] == ["worker"])
    table = lines[header:header + 3]
    assert table[1].split()[0] == workers[0].worker and "SILENT none yet" in table[1]
    assert len({len(line) for line in table}) == 1  # the right-aligned columns end where their headers do
    for title in ("capacity", "load", "of ours", "heartbeat", "sent", "failed"):
        end = table[0].index(title) + len(title)
        assert table[1][end - 1] != " " and table[2][end - 1] != " " and table[1][end:end + 1] in ("", " "), title


def test_status_says_when_the_disk_is_too_full_for_new_jobs():
    mb = 1024 * 1024
    disk = DiskUsage(recordings=5 * mb, pictures=0, store=mb, other=0, free_on_disk=3 * mb)
    status = CellStatus(cell="bay", started=0.0, time=30.0, workers={"robot": True, "camera": True},
                        reconstructors=[], queued=0, max_queued=100, waiting_for_reconstructor=0,
                        jobs={"succeeded": 3}, recent_failures=[], disk=disk)
    lines = format_status(status).splitlines()
    assert "disk FULL: no new job is taken until 8 MB are free on it" in lines
    roomy = format_status(status.model_copy(update={"disk": disk.model_copy(update={"free_on_disk": 900 * mb})}))
    assert "FULL" not in roomy


# --- replay --------------------------------------------------------------------------------------------

@pytest.fixture
def recording(tmp_path):
    """A run directory with one job's recording, and the configuration that names it."""
    from robocell.cell.recording import JobRecording

    run_dir = tmp_path / "runs"
    with JobRecording(run_dir / "j1.rrd", "j1") as rec:
        rec.log_text("moving")
    config = tmp_path / "cell.toml"
    config.write_text(f"run_dir = '{run_dir}'\n")
    return config, run_dir


def test_replay_opens_only_the_run_directory(recording, tmp_path, capsys):
    config, run_dir = recording
    elsewhere = tmp_path / "elsewhere.rrd"
    shutil.copy(run_dir / "j1.rrd", elsewhere)
    for given in (str(elsewhere), "../elsewhere"):
        assert main(["replay", given, "--web", "--config", str(config)]) == 1
        assert f"robocell replay: {given} is not in the run directory {run_dir}" in capsys.readouterr().err


def test_replay_without_a_display_says_to_use_web(recording, monkeypatch, capsys):
    config, _ = recording
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    assert main(["replay", "j1", "--config", str(config)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("robocell replay: no display") and "use --web" in err and err.count("\n") == 1


def _listening(port: int) -> list[str]:
    """The local addresses of the TCP sockets listening on ``port`` (IPv4 and IPv6)."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, _, hex_port = local.partition(":")
            if state == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
                found.append(address)
    return found


@pytest.mark.parametrize("stop", ["ctrl-c", "kill"])
def test_replay_web_prints_the_address_that_opens_the_recording_and_ctrl_c_or_kill_ends_it(recording, stop):
    config, run_dir = recording
    web_port, grpc_port = free_port(), free_port()
    # As from a terminal: Ctrl-C not ignored (a test run started in the background inherits it ignored).
    process = subprocess.Popen([sys.executable, "-m", "robocell", "replay", "j1", "--web", "--config", str(config),
                                "--web-port", str(web_port), "--grpc-port", str(grpc_port)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        line = process.stdout.readline()
        address = f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy"
        assert line == f"serving {run_dir / 'j1.rrd'}: open {address} (Ctrl-C stops)\n"
        wait_until(lambda: _listening(web_port) and _listening(grpc_port), timeout=30, interval=0.1,
                   what="the viewer's servers")
        assert set(_listening(web_port) + _listening(grpc_port)) == {"0100007F"}  # 127.0.0.1 only
        if stop == "ctrl-c":
            os.killpg(process.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the whole foreground group
        else:
            process.terminate()  # robocell alone: it stops the viewer
        _, stderr = process.communicate(timeout=30)  # the viewer gone too: it held the same pipes
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate(timeout=30)
    assert process.returncode == 0 and "Traceback" not in stderr and "KeyboardInterrupt" not in stderr


def test_background_takes_the_views_of_a_scan_and_checks_its_poses_first(tmp_path, capsys):
    """``robocell background`` is a scan's views without the scan: the same --target or --poses,
    the same one-line error for a bad poses file, no --pick."""
    (tmp_path / "one-pose.json").write_text(json.dumps([np.eye(4).tolist()]))
    assert main(["background", "--poses", str(tmp_path / "one-pose.json")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == (f"robocell background: {tmp_path / 'one-pose.json'}: flange_poses: List should have "
                                 f"at least 2 items after validation, not 1\n")
    with pytest.raises(SystemExit):
        main(["background", "--target", "0.6", "0", "0.05", "--pick"])
    assert "unrecognized arguments: --pick" in capsys.readouterr().err


def test_scan_place_goes_with_pick(capsys):
    """Checked before anything is sent."""
    assert main(["scan", "--target", "0.6", "0", "0.05", "--place", "0.6", "0.2"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == "robocell scan: --place goes with --pick\n"


def _held_port() -> socket.socket:
    """A port this test process listens on."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen()
    return listener


def test_up_names_the_process_that_holds_the_routers_port(tmp_path):
    import asyncio

    from robocell.cli.demo import local_config
    from robocell.cli.up import CellProcesses
    from robocell.wire.errors import CellError

    with _held_port() as listener:
        port = listener.getsockname()[1]
        config = local_config(tmp_path / "runs", zenoh={"router": f"tcp/127.0.0.1:{port}"})
        cell = CellProcesses(config)
        with pytest.raises(CellError) as raised:
            asyncio.run(cell.start(ready_timeout=5))
    assert str(raised.value).startswith(f"the router's port {port} on 127.0.0.1 is in use by process {os.getpid()} (")
    assert "give [zenoh] router another port" in str(raised.value)
    assert all(child.process is None for child in cell.children)  # nothing was started


def test_replay_web_on_a_held_port_says_so_before_any_address(recording, capsys):
    config, _ = recording
    with _held_port() as listener:
        port = listener.getsockname()[1]
        assert main(["--config", str(config), "replay", "j1", "--web", "--web-port", str(port)]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith(f"robocell replay: port {port} on 127.0.0.1 is in use by process {os.getpid()} (")
    assert err.rstrip().endswith("give --web-port another port")


def test_camera_probe_logs_no_library_chatter(tmp_path):
    """httpx logs each request at INFO: left out unless -v."""
    from robocell.wire.config import SimConfig
    from robocell.workers.sim.axis import SimCameraServer
    from robocell.workers.sim.scans import default_K, look_at
    from robocell.workers.sim.scene import scene_from_config

    size = (320, 240)
    pose = look_at([0.85, 0.25, 0.35], [0.6, 0.0, 0.02])
    with SimCameraServer(scene_from_config(SimConfig()), K=default_K(size), image_size=size,
                         pose_provider=lambda: pose) as camera:
        # A printed scene renders for seconds on a busy machine: the probe waits for it.
        probe = ["camera", "probe", camera.url, "--timeout", "30", "--resolution", "320x240"]
        quiet = subprocess.run([sys.executable, "-m", "robocell", *probe], capture_output=True, text=True, timeout=120)
        verbose = subprocess.run([sys.executable, "-m", "robocell", "-v", *probe], capture_output=True, text=True,
                                 timeout=120)
    assert quiet.returncode == 0, quiet.stderr
    assert "snapshot     ok" in quiet.stdout
    assert quiet.stderr == ""
    assert "httpx" in verbose.stderr  # what was left out is there to be asked for


def test_a_router_on_a_held_port_names_its_holder(tmp_path, capsys):
    with _held_port() as listener:
        port = listener.getsockname()[1]
        assert main(["router", "--listen", f"tcp/127.0.0.1:{port}"]) == 1
    err = capsys.readouterr().err
    holder = f"process {os.getpid()} ("
    assert err.startswith(f"robocell router: the router's port {port} on 127.0.0.1 is in use by {holder}")
    assert err.rstrip().endswith("give --listen or [zenoh] router another port")
