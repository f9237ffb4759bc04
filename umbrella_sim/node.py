"""``python -m umbrella_sim.node``: umbrella_node (the node is ``umbrella_sim.ros.node``)."""
if __name__ == "__main__":
    from umbrella_sim.tools.entry import node_main

    raise SystemExit(node_main())
