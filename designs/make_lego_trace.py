"""Write designs/lego_trace.csv: θ at units 4, 8, ..., 24 of designs/lego_chain_scene.yaml every
0.25 ms for 50 ms (201 times), with Gaussian noise of 0.005 rad std (seed 17): the data of the fit
showcase designs/lego_fit.yaml. Run: python designs/make_lego_trace.py
"""

from pathlib import Path

from flexmm.config.loader import read_yaml
from flexmm.design.fit import synthetic_table, write_table

HERE = Path(__file__).resolve().parent
SITES = [4, 8, 12, 16, 20, 24]


def main() -> None:
    data, _ = read_yaml(HERE / "lego_chain_scene.yaml")
    table = synthetic_table(data, "theta", SITES, 250e-6, 201, noise=0.005, seed=17, base_dir=HERE)
    write_table(table, HERE / "lego_trace.csv", "rad")


if __name__ == "__main__":
    main()
