"""One version, written in package.xml: setup.py, the package and the command line agree."""

import importlib.metadata
import json
from pathlib import Path
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

import threat_planner
from threat_planner import _version

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sys.executable).with_name('threat-planner')


def manifest_version() -> str:
    return ET.parse(ROOT / 'package.xml').getroot().findtext('version').strip()


def test_setup_py_the_package_and_the_command_line_say_package_xml_s_version():
    setup_py = subprocess.run([sys.executable, 'setup.py', '--version'], cwd=ROOT,
                              capture_output=True, text=True, timeout=120)
    assert setup_py.returncode == 0, setup_py.stderr
    if not SCRIPT.exists():
        pytest.skip(f'no threat-planner script beside {sys.executable}')
    cli = subprocess.run([str(SCRIPT), '--version'], capture_output=True, text=True,
                         timeout=120)
    assert cli.returncode == 0, cli.stderr
    version = manifest_version()
    assert setup_py.stdout.strip().splitlines()[-1] == version
    assert cli.stdout.strip() == f'threat-planner {version}'
    assert threat_planner.__version__ == version


def test_the_version_is_a_release_number():
    """major.minor.patch, as bloom and PEP 440 both read it."""
    assert [part.isdigit() for part in manifest_version().split('.')] == [True] * 3


def test_importing_the_package_reads_no_version_until_asked():
    """``import threat_planner`` stays cheap: no XML parser, no metadata lookup."""
    probe = ('import json, sys\n'
             'before = set(sys.modules)\n'
             'import threat_planner\n'
             'loaded = set(sys.modules) - before\n'
             'print(json.dumps(sorted(m for m in loaded if m.startswith(('
             '"xml", "importlib.metadata", "threat_planner._version")))))\n')
    p = subprocess.run([sys.executable, '-c', probe], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout) == []


def test_a_checkout_reads_its_package_xml_before_the_installed_metadata(monkeypatch, tmp_path):
    """An editable install's metadata keeps the version of its last ``pip install -e``."""
    monkeypatch.setattr(_version, 'CHECKOUT_PACKAGE_XML', ROOT / 'package.xml')
    assert _version.version() == manifest_version()
    monkeypatch.setattr(_version, 'CHECKOUT_PACKAGE_XML', tmp_path / 'package.xml')
    try:
        installed = importlib.metadata.version('threat_planner')
    except importlib.metadata.PackageNotFoundError:
        installed = '0+unknown'
    assert _version.version() == installed


@pytest.mark.parametrize('text', [
    '<package format="3"><name>other_package</name><version>9.9.9</version></package>',
    '<package format="3"><name>threat_planner</name></package>',
    '<package format="3"><name>threat_planner</name><version>',
    'not xml at all',
])
def test_a_manifest_that_is_not_ours_or_is_broken_gives_no_version(tmp_path, text):
    (tmp_path / 'package.xml').write_text(text)
    assert _version.package_xml_version(tmp_path / 'package.xml') is None
    assert _version.package_xml_version(tmp_path / 'missing.xml') is None
