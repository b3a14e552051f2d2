"""The shipped RViz config and Foxglove layout parse and name the node's real topics."""

import json
from pathlib import Path
import re

import yaml

from threat_planner.ros.interface import INPUT_TOPICS, OUTPUT_TOPICS

REPO = Path(__file__).resolve().parents[2]
KNOWN = {'/' + t for t in {**INPUT_TOPICS, **OUTPUT_TOPICS}}
SHOWN = {'/path', '/initial_path', '/network', '/no_fly_zones'}


def rviz_topics(node, out):
    if isinstance(node, dict):
        topic = node.get('Topic')
        if isinstance(topic, dict):
            out.append(topic['Value'])
        for value in node.values():
            rviz_topics(value, out)
    elif isinstance(node, list):
        for value in node:
            rviz_topics(value, out)
    return out


def test_rviz_config_parses_and_shows_the_node_outputs():
    config = yaml.safe_load((REPO / 'rviz' / 'threat_planner.rviz').read_text())
    assert config['Visualization Manager']['Global Options']['Fixed Frame'] == 'map'
    topics = rviz_topics(config, [])
    assert set(topics) <= KNOWN, set(topics) - KNOWN
    assert SHOWN <= set(topics)


def test_foxglove_layout_parses_and_shows_the_node_outputs():
    text = (REPO / 'foxglove' / 'threat_planner.json').read_text()
    json.loads(text)
    topics = set(re.findall(r'"(/[a-z_]+)', text))
    assert topics <= KNOWN, topics - KNOWN
    assert SHOWN | {'/plan_info'} <= topics


def test_setup_installs_both_files():
    setup = (REPO / 'setup.py').read_text()
    assert "glob('rviz/*.rviz')" in setup and "glob('foxglove/*.json')" in setup
