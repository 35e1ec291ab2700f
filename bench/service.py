"""Service benchmark: submit latency (p50/p99), throughput of small convert jobs with 2 workers, and the
end-to-end overhead of a convert job over the CLI and over the library call, on one `amprep serve`, in one run.

    python bench/service.py [--submits 200] [--jobs 60] [--part voron_vhb_din_mount.step]

Prints a table and writes docs/bench_service.md and docs/bench_service.csv.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
CORPUS = Path(os.environ.get("AMPREP_CORPUS", ROOT.parent / "shared" / "corpus"))
sys.path.insert(0, str(ROOT))

from amprep.serve import free_port  # noqa: E402


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(q / 100 * (len(s) - 1))))]


def wait_all(c: httpx.Client, ids: list[str], timeout: float = 900) -> list[dict]:
    deadline, done = time.monotonic() + timeout, {}
    while len(done) < len(ids):
        for job_id in ids:
            if job_id not in done:
                j = c.get(f"/v1/jobs/{job_id}").json()
                if j["status"] in ("succeeded", "failed", "cancelled"):
                    done[job_id] = j
        if time.monotonic() > deadline:
            raise TimeoutError("jobs did not finish")
        time.sleep(0.05)
    return [done[i] for i in ids]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--submits", type=int, default=200)
    ap.add_argument("--jobs", type=int, default=60)
    ap.add_argument("--part", default="voron_vhb_din_mount.step")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    part = CORPUS / args.part
    data = Path(tempfile.mkdtemp(prefix="amprep-bench-"))
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("AMPREP_")}
    serve = subprocess.Popen([sys.executable, "-m", "amprep", "serve", "--port", str(port), "--data", str(data),
                              "--workers", "2"], env=env, cwd=ROOT, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    rows: list[tuple[str, float, str]] = []
    try:
        c = httpx.Client(base_url=url, timeout=600)
        deadline = time.monotonic() + 120
        while True:
            try:
                if c.get("/readyz").status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                raise SystemExit("amprep serve did not become ready")
            time.sleep(0.2)
        body = part.read_bytes()

        def post(params: str = '{"reuse": false}', wait: float = 0, accept: str | None = None) -> httpx.Response:
            return c.post("/v1/jobs", params={"wait": wait} if wait else None,
                          data={"kind": "convert", "params": params}, files={"file": (part.name, body)},
                          headers={"Accept": accept} if accept else {})

        # warm-up: both worker processes have imported OCCT and met the part once
        wait_all(c, [post().json()["id"] for _ in range(4)])

        # 1. submit latency while the queue fills (the request returns when the job is stored and enqueued)
        lat, ids = [], []
        for _ in range(args.submits):
            t0 = time.perf_counter()
            r = post()
            lat.append((time.perf_counter() - t0) * 1000)
            ids.append(r.json()["id"])
        wait_all(c, ids)
        rows += [("submit latency p50", pct(lat, 50), "ms"), ("submit latency p99", pct(lat, 99), "ms")]

        # 2. throughput: N jobs submitted from 8 client threads, first submit to last finish
        t0 = time.perf_counter()
        with ThreadPoolExecutor(8) as pool:
            ids = [r.json()["id"] for r in pool.map(lambda _: post(), range(args.jobs))]
        jobs = wait_all(c, ids)
        span = time.perf_counter() - t0
        assert all(j["status"] == "succeeded" for j in jobs)
        rows.append(("throughput, 2 workers", args.jobs / span, "jobs/s"))

        # 3. one job end to end (idle service, ?wait, Accept: model/stl) vs the CLI vs the library call
        e2e = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            r = post(wait=600, accept="model/stl")
            assert r.status_code == 200
            e2e.append(time.perf_counter() - t)
        out = data / "cli.stl"
        cli = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "amprep", "convert", str(part), "-o", str(out), "--quiet"],
                           check=True, cwd=ROOT)
            cli.append(time.perf_counter() - t)
        lib_code = ("import time,sys; from amprep.jobs.convert import convert, write_result; convert(sys.argv[1])\n"
                    "for _ in range(int(sys.argv[3])):\n"
                    "    t=time.perf_counter(); r=convert(sys.argv[1]); write_result(r, sys.argv[2]);"
                    " print(time.perf_counter()-t)")
        lib = [float(x) for x in subprocess.run([sys.executable, "-c", lib_code, str(part), str(out), str(args.repeat)],
                                                check=True, capture_output=True, text=True).stdout.split()]
        m_e2e, m_cli, m_lib = (statistics.median(x) for x in (e2e, cli, lib))
        rows += [("convert job end to end (median)", m_e2e * 1000, "ms"),
                 ("amprep convert CLI (median, new process)", m_cli * 1000, "ms"),
                 ("library convert + write (median, warm process)", m_lib * 1000, "ms"),
                 ("job / CLI", m_e2e / m_cli, "ratio"),
                 ("job - library (service overhead)", (m_e2e - m_lib) * 1000, "ms")]
    finally:
        os.killpg(serve.pid, signal.SIGINT)
        serve.wait(60)
        shutil.rmtree(data, ignore_errors=True)  # the service's Redis dump, jobs and logs

    title = f"Service benchmark: `{args.part}`, `amprep serve --workers 2`, 2-core VM"
    lines = [f"# {title}", "", "| measure | value | unit |", "|---|---:|---|"]
    lines += [f"| {name} | {value:.3g} | {unit} |" for name, value, unit in rows]
    lines += ["", f"{args.submits} sequential submits for the latency; {args.jobs} jobs from 8 client threads for the "
              f"throughput; {args.repeat} runs each for the end-to-end comparison. Written by bench/service.py."]
    text = "\n".join(lines) + "\n"
    print(text)
    (ROOT / "docs" / "bench_service.md").write_text(text)
    with (ROOT / "docs" / "bench_service.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["measure", "value", "unit"])
        w.writerows(rows)


if __name__ == "__main__":
    main()
