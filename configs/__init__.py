"""Scene files shipped with rss6, installed as the data package ``pipeline.scene_files``."""
