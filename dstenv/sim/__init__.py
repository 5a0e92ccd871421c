"""The 2-D urban world simulator (pure numpy + numba, no gymnasium).

``default_config()`` gives the ``world`` configuration section; :class:`World`
steps a map, traffic agents and an ego vehicle. Maps come from the procedural
city generator (:func:`generate_city`) or from OpenStreetMap files
(:func:`dstenv.sim.osm.load_osm`).
"""

from dstenv.sim.citygen import generate_city
from dstenv.sim.config import default_config
from dstenv.sim.lanes import LaneNetwork
from dstenv.sim.types import AgentKind, Agents, MapClass, WorldMap
from dstenv.sim.world import World

__all__ = ["default_config", "World", "generate_city", "LaneNetwork", "WorldMap", "Agents",
           "MapClass", "AgentKind"]
