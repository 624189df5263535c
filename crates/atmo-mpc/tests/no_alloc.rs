// placeholder created by the lead so the workspace manifest parses; the MPC helper replaces it
