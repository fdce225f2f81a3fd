"""Scene files shipped with rss6 (installed as the package ``rss6_configs``)."""
