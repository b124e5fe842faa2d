#!/usr/bin/env python3
"""Bake a map's page files on a Dask cluster, one task per share of the pages.

Each task runs `worldgen bake MAP --share K/N` on a worker. A page's bytes depend only on its
layer and its index, so the shares may run in any order on any workers and together write the
same bytes as `worldgen bake MAP` on one machine. When every share is done, the driver runs
`worldgen bake MAP --finish`, which checks every page and only then moves the files into place.

The map folder must be reachable at the same path by every worker: a local folder for a local
cluster, a shared file system for a cluster of machines. Every worker reads the map's layers
whole (the source map is not paged yet).

    python bake.py MAP --local-workers 2          # a local cluster of two worker processes
    python bake.py MAP --scheduler tcp://host:8786 --shares 64
"""

import argparse
import subprocess
import sys
import time


def bake_share(worldgen, map_dir, part, count, page_side):
    """Runs one share of the bake; returns (share, worker, seconds, worldgen's report)."""
    from dask.distributed import get_worker

    t0 = time.monotonic()
    done = subprocess.run(
        [worldgen, "bake", map_dir, "--quiet", "--page-side", str(page_side),
         "--share", f"{part}/{count}"],
        capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"share {part}/{count}: {done.stderr.strip()}")
    return part, get_worker().address, time.monotonic() - t0, done.stdout.strip()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("map", help="the map folder (the same path on every worker)")
    parser.add_argument("--worldgen", default="target/release/worldgen",
                        help="the worldgen binary (the same path on every worker)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--scheduler", help="address of a running Dask scheduler")
    where.add_argument("--local-workers", type=int, default=2,
                       help="start a local cluster of this many worker processes (default 2)")
    parser.add_argument("--shares", type=int, default=0,
                        help="number of tasks (default: twice the number of workers)")
    parser.add_argument("--page-side", type=int, default=256, help="samples per page side")
    args = parser.parse_args()

    from dask.distributed import Client, LocalCluster

    if args.scheduler:
        client = Client(args.scheduler)
        cluster = None
    else:
        if args.local_workers < 1:
            parser.error("--local-workers must be at least 1")
        cluster = LocalCluster(n_workers=args.local_workers, threads_per_worker=1,
                               processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        if cluster is not None:
            client.wait_for_workers(args.local_workers)
        workers = sorted(client.scheduler_info()["workers"])
        if not workers:
            parser.error("the cluster has no workers")
        shares = args.shares or 2 * len(workers)
        t0 = time.monotonic()
        # Shares are equal, so they are dealt out in turn; a share may move to another worker
        # only if its own is gone.
        futures = [client.submit(bake_share, args.worldgen, args.map, k, shares, args.page_side,
                                 key=f"bake-share-{k}-of-{shares}", pure=False,
                                 workers=[workers[k % len(workers)]], allow_other_workers=True)
                   for k in range(shares)]
        for part, worker, seconds, report in client.gather(futures):
            print(f"share {part}/{shares} on worker {worker}: {seconds:.2f} s: {report}")
        print(f"{shares} shares on {len(workers)} workers: {time.monotonic() - t0:.2f} s")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    done = subprocess.run([args.worldgen, "bake", args.map, "--quiet", "--finish"])
    return done.returncode


if __name__ == "__main__":
    sys.exit(main())
