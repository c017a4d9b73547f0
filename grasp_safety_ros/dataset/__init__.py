"""Safety labels for grasp datasets: ``grasp-safety batch`` (SPEC file, dataset readers, Arrow
schema, report rows, and the chunked batch on the package's pool or a Dask cluster).

An adapter like ``cli``: ``dask``, ``distributed``, ``pyarrow``, ``h5py`` and ``tqdm`` are
imported here only, inside the functions that need them.
"""
