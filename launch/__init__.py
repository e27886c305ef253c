"""The cell as one product: docker-compose.yml run as local processes (lamps up), recording and run report."""
