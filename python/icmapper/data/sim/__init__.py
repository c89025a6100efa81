"""Synthetic data: procedural cities (city), the ego driver (driver), the nuScenes-like camera rig
(rig), the ground-plane ray-casting camera renderer (renderer, composing rays, paint, texture,
vehicles and sensor) and sequences tying them together."""

from icmapper.data.sim.city import CITY_SEEDS, generate_city
from icmapper.data.sim.driver import drive
from icmapper.data.sim.renderer import Renderer
from icmapper.data.sim.rig import nuscenes_rig, project_ego_points
from icmapper.data.sim.sequences import sim_city_drives, sim_sequence, sim_sequences

__all__ = [
    "sim_city_drives",
    "CITY_SEEDS",
    "Renderer",
    "drive",
    "generate_city",
    "nuscenes_rig",
    "project_ego_points",
    "sim_sequence",
    "sim_sequences",
]
