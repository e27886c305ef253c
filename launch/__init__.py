"""The cell as one product: docker-compose.yml run as local processes (lamps up), recording and run report."""

__all__ = [
    "background_node", "bench", "campaign", "campaign_bounds", "campaign_cells", "campaign_plants", "campaign_pool",
    "campaign_ray", "campaign_run", "campaign_table", "campaign_worker", "cli", "compose", "compose_interp", "folders",
    "health", "layout", "learn", "live", "local_cell", "procs", "record", "record_budget", "record_cli", "record_json",
    "record_sink", "report", "report_faults", "report_maths", "report_options", "report_plots", "report_run",
    "report_sources", "router", "run_end", "scene", "schemas", "site", "teach", "teach_cell", "teach_hand", "ws_server"
]
