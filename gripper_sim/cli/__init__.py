"""The ``gripper-sim`` command line: thin verbs over the core, the node and the recorder."""
