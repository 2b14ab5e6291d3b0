"""Dataset pipeline: configs, randomization, sampling, jobs and workers, shards, HDF5, previews, exports."""
