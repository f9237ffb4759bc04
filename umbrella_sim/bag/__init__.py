"""
The recording format: MCAP files in rosbag2 bag directories, written and read.

    format       the record names and constants writer and readers share
    cdr          messages as a recording stores them: definitions, exact CDR bytes, QoS
    writer, mcap_stream
                 BagRecorder: a crash-safe bag directory, never overwriting
    reader       read_log: a bag directory or a single .mcap, finalised, torn or ended early
    provenance   the run records that make a recording reproducible from the file alone
    paths        checks of input and output paths, made before any expensive work

It runs no node and handles no signal; it knows the core's records only through the
objects it is handed.
"""
