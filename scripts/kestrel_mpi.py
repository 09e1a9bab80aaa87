"""Running kestrel's renders over MPI from the dataset scripts: `--mpi N [--hostfile F]`
launches each `kestrel render-sequence` as `mpirun -n N kestrel ...`, so every frame of every
clip is rendered image-parallel over N ranks (dynamic tiles, the same bits as one process;
docs/distributed.md)."""
import os


def add_arguments(ap):
    ap.add_argument("--mpi", type=int, default=0, metavar="N",
                    help="render each clip with `mpirun -n N` (distributed tiles; same bits as one process)")
    ap.add_argument("--hostfile", help="mpirun --hostfile: the machines for --mpi (default: this one, oversubscribed)")


def prefix(args):
    """The mpirun words to put before a kestrel command ([] without --mpi)."""
    if not args.mpi or args.mpi <= 1:
        return []
    cmd = ["mpirun", "-n", str(args.mpi)]
    cmd += ["--hostfile", args.hostfile] if args.hostfile else ["--oversubscribe"]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    return cmd
