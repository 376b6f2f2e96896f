"""A fleet re-identification on Dask: every machine's record is one ambid workflow run, spread
over the workers of a cluster; the results come back as one table with each plant's drift from
its reference model.

    python examples/fleet.py                       # a LocalCluster of 2 worker processes
    python examples/fleet.py tcp://scheduler:8786  # unchanged, on a real cluster

Here the "fleet" is the embedded twin: 16 random test rigs (other masses, magnets, controllers,
noise), each identified twice (two noise seeds), against the nominal rig's model as reference.
With recorded data, build the records with ``Record(name, workflow_toml, base=directory)`` or
``Record.from_arrays(name, r=..., u=..., y=..., fs=...)`` instead. Needs ``dask[distributed]``
(and pandas for the printed table).
"""

import sys

import ambid.batch as batch


def main() -> None:
    from dask.distributed import Client, LocalCluster

    steps = ["frf", "order", "models", "pole_zero", "validation", "iso"]
    reference_run = batch.identify([batch.Record.twin("reference", seed=1, steps=steps)])
    row = reference_run.rows[0]
    reference = reference_run.models["reference"][batch.model_key(row["chosen_model"])]

    records = [
        batch.Record.twin(f"rig{rig:02d}-run{run}", seed=100 * rig + run, rig_seed=rig, steps=steps)
        for rig in range(1, 17)
        for run in (1, 2)
    ]
    if len(sys.argv) > 1:
        client = Client(sys.argv[1])
    else:
        client = Client(LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None))
    with client:
        result = batch.identify(records, engine="dask", client=client, reference=reference)
    try:
        print(result.to_pandas()[["record", "status", "chosen_model", "fit_y_pct", "iso_zone", "unstable_poles", "drift"]])
    except ImportError:
        for r in result.rows:
            print(r)


if __name__ == "__main__":
    main()
