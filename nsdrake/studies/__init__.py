"""Many runs compared: ``nsdrake compare`` (families of variants and their measures) and
``nsdrake sweep`` (grids and random samples of a scenario's fields, on local processes
or a Dask cluster)."""
