"""
The ROS 2 face: the node, its messages and parameters, the deploy controller, launch.

    node, node_main    umbrella_node (a thin adapter around core.driver.RunDriver) and its process
    pacing, lockstep   real-time pacing; the co-simulation handshake
    commands           the sleeve_force intake: checked, counted, recorded, held
    messages, publication
                       topics, QoS, Sample -> messages; a publication's CDR bytes
    recording          a run's channels and records on a bag (the node and record_offline)
    parameters, params_file
                       typed, ranged descriptors from the registry, why a runtime set is
                       refused; ROS params files
    deploy_controller  the closed-loop controller node (the law: core.control)
    launch_description, robot_description
                       what the launch files start; the URDF
    signals, share     stop signals as requests; where the package's data files are

Importing this package imports nothing: the entry points install the signal handlers
before any heavy import.
"""
