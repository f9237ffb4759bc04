"""
The command lines: umbrella_sim (simulate, sweep), umbrella_replay, umbrella_compare.

    entry              the console scripts (signal handlers first, then the tool)
    cli, inputs, csv_output, progress
                       umbrella_sim simulate: its options, inputs, CSV, progress line
    sweep, sweep_spec, sweep_results
                       umbrella_sim sweep: the SPEC, the Dask run, the table and plots
    replay             republish a recording, or re-simulate and check it
    compare, runs, compare_plots
                       compare recorded runs: table, JSON, plots
    param_docs         the parameter tables of msg_docs/
"""
