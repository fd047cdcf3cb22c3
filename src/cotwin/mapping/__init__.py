"""Platform mapping: the paper's platform-mapping interface generated from the mapping model, its
endpoints (the MuJoCo simulator, a robot behind a broker) and its FMU."""
