"""CloudSim: cloud-hosted, real-time robot simulation competitions."""

# The one place the version is written: the package metadata, `cloudsim --version`, the pages'
# footer and the API's OpenAPI document read it.
__version__ = "0.1.0"
