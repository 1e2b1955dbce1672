"""``python -m sctd_services.input``: the same as ``sctd input``."""

import argparse
import sys

from . import add_arguments, run

if __name__ == "__main__":
    parser = argparse.ArgumentParser(prog="sctd input")
    add_arguments(parser)
    sys.exit(run(parser.parse_args()))
