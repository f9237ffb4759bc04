"""``python -m umbrella_sim.deploy_controller``: the closed-loop deploy controller node."""
if __name__ == "__main__":
    from umbrella_sim.tools.entry import controller_main

    raise SystemExit(controller_main())
