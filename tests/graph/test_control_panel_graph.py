"""The control panel in a real browser: headless Chromium (Debian's `chromium` and
`chromium-driver`, driven by Selenium; nothing downloads a browser) drives the simulated mini
robot, and the robot's own odometry, read here independently of the page, says what it did."""
import os
import re
import shutil
import statistics
from pathlib import Path

import pytest
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock

from helpers import wait_for
from ros_common.stamps import to_seconds

CHROMIUM, DRIVER = shutil.which('chromium'), shutil.which('chromedriver')
MAX_SPEED = 0.2             # the mini robot's (the simulator's max_speed)


@pytest.fixture
def browser(tmp_path):
    if not (CHROMIUM and DRIVER):
        if os.geteuid() == 0:
            pytest.fail('chromium and chromium-driver are missing: scripts/setup.sh installs '
                        'them (apt-get install chromium chromium-driver)')
        pytest.skip('needs chromium and chromium-driver (as root: apt-get install chromium '
                    'chromium-driver)')
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ('--headless=new', '--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage',
                '--window-size=1280,1000', '--disable-background-timer-throttling',
                '--disable-renderer-backgrounding', f'--user-data-dir={tmp_path / "chromium"}'):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    driver.implicitly_wait(0)
    yield driver
    try:
        driver.quit()
    except Exception:  # noqa: BLE001 - a test may have closed it already
        pass


class Robot:
    """The mini robot as its odometry and the simulator's clock tell it."""

    def __init__(self, probe) -> None:
        self.clock = probe.collect(Clock, '/clock', qos=10)
        self.odom = probe.collect(Odometry, '/mini_robot/odom', qos=1000)

    def now(self) -> float:
        return to_seconds(self.clock[-1][1].clock)

    def x(self) -> float:
        return self.odom[-1][1].pose.pose.position.x

    def speed(self) -> float:
        return self.odom[-1][1].twist.twist.linear.x

    def speeds_since(self, t: float):
        return [m.twist.twist.linear.x for _, m in list(self.odom)
                if to_seconds(m.header.stamp) >= t]

    def wait_until(self, t: float, what: str) -> None:
        wait_for(lambda: self.now() >= t, 60.0, what=what)

    def stopped(self) -> bool:
        return abs(self.speed()) < 0.005

    def moving(self) -> bool:
        return self.speed() > 0.05


def test_the_reports_panel_drives_the_robot_in_a_browser(start_node, probe, browser, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    start_node('sim_node', '-p', 'real_time_factor:=1.0')
    panel = start_node('control_panel', '-p', 'port:=0')
    wait_for(lambda: re.search(r'on (http://127\.0\.0\.1:\d+/)', panel.output())
             or not panel.alive(), 30.0, what='the panel to serve')
    url = re.search(r'on (http://127\.0\.0\.1:\d+/)', panel.output()).group(1)
    robot = Robot(probe)
    wait_for(lambda: robot.clock and robot.odom, 30.0, what='the simulator')

    browser.get(url)
    find = browser.find_element

    def text(element_id):
        return find(By.ID, element_id).text

    wait_for(lambda: text('status') == 'connected'
             and '/mini_robot' in text('robot') and text('odom_x') != '–', 30.0,
             what='the page to show the robot')
    # A differential drive: no strafe buttons; the report's turn option is offered.
    assert not find(By.ID, 'strafe_left').is_displayed()
    assert find(By.ID, 'report_turns_option').is_displayed()
    assert text('speed_value') == '50 %'
    assert not find(By.ID, 'cell').is_displayed()           # (no coordinator runs)

    # 1. Hold forward for 2 s of simulated time, at the slider's 50 %: 0.1 m/s.
    forward = find(By.ID, 'forward')
    x0 = robot.x()
    ActionChains(browser).click_and_hold(forward).perform()
    wait_for(robot.moving, 10.0, what='the robot to drive off')
    t0 = robot.now()
    robot.wait_until(t0 + 2.0, '2 s of simulated time')
    ActionChains(browser).release(forward).perform()
    wait_for(robot.stopped, 10.0, what='the robot to stop after the release')
    steady = statistics.median(robot.speeds_since(t0 + 0.3)[:100])
    assert steady == pytest.approx(0.5 * MAX_SPEED, rel=0.05)
    travelled = robot.x() - x0
    # About 2 s at 0.1 m/s, plus the start before t0 (its ramp at 1 m/s^2 is 5 mm).
    assert 0.19 < travelled < 0.30, travelled
    assert 'stopped: released' in panel.output()

    # 2. The slider to 100 % (the keyboard on the slider, as a user would): the speed follows.
    slider = find(By.ID, 'speed')
    slider.send_keys(Keys.END)
    wait_for(lambda: text('speed_value') == '100 %', 5.0, what='the slider at 100 %')
    body = find(By.TAG_NAME, 'body')
    ActionChains(browser).move_to_element(body).key_down('w').perform()    # the teleop key
    wait_for(robot.moving, 10.0, what='the robot to drive off')
    t1 = robot.now()
    robot.wait_until(t1 + 1.0, '1 s at full speed')
    assert statistics.median(robot.speeds_since(t1 + 0.3)) == pytest.approx(MAX_SPEED, rel=0.05)
    assert 'forward: vx 0.200' in text('command')
    browser.save_screenshot(str(tmp_path / 'control_panel.png'))
    if os.environ.get('PANEL_SCREENSHOT'):
        Path(os.environ['PANEL_SCREENSHOT']).parent.mkdir(parents=True, exist_ok=True)
        browser.save_screenshot(os.environ['PANEL_SCREENSHOT'])
    # ... and the stop button stops it, the key still down.
    find(By.ID, 'stop').click()
    wait_for(robot.stopped, 10.0, what='the robot to stop on the stop button')
    ActionChains(browser).key_up('w').perform()
    assert 'stopped: stop pressed' in panel.output()

    # 3. A page that goes silent while holding (frozen, its repeats gone): the dead man.
    ActionChains(browser).key_down('w').perform()
    wait_for(robot.moving, 10.0, what='the robot to drive off')
    browser.execute_script('clearInterval(heartbeat);')
    wait_for(robot.stopped, 10.0, what='the robot to stop when the page goes silent')
    assert 'stopped: no word from the page' in panel.output()
    ActionChains(browser).key_up('w').perform()

    # 4. The page closed while driving: the robot stops.
    ActionChains(browser).key_down('w').perform()
    wait_for(robot.moving, 10.0, what='the robot to drive off')
    t_close = robot.now()
    browser.quit()
    wait_for(robot.stopped, 10.0, what='the robot to stop when the page is closed')
    stamp = next(to_seconds(m.header.stamp) for _, m in list(robot.odom)
                 if to_seconds(m.header.stamp) > t_close and abs(m.twist.twist.linear.x) < 0.005)
    assert stamp - t_close < 1.0            # within the simulator's cmd_vel_timeout, and more
    # (The closing page says it lets go; a page that vanishes without a word is stopped by
    # the server when its connection goes, or by the dead man, as in 3.)
    wait_for(lambda: 'page 1 left' in panel.output(), 10.0, what='the panel to see it go')
    assert panel.alive()
    assert (tmp_path / 'control_panel.png').stat().st_size > 10000


def test_the_panel_shows_a_holonomic_base_and_the_pipelines_state(start_node, probe, browser):
    """The youBot: strafe buttons and no report turn option; what the coordinator publishes
    (its latched state and its events, here from the test) appears on the page."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from sim_interfaces.msg import PipelineEvent, PipelineState

    start_node('sim_node', '-p', 'world:=package://world_description/worlds/youbot.yaml')
    panel = start_node('control_panel', '-p', 'port:=0')
    wait_for(lambda: re.search(r'on (http://127\.0\.0\.1:\d+/)', panel.output())
             or not panel.alive(), 30.0, what='the panel to serve')
    url = re.search(r'on (http://127\.0\.0\.1:\d+/)', panel.output()).group(1)
    odom = probe.collect(Odometry, '/youbot/odom', qos=1000)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    state_pub = probe.node.create_publisher(PipelineState, '/coordinator_node/state', latched)
    event_pub = probe.node.create_publisher(PipelineEvent, '/coordinator_node/events', 100)
    browser.get(url)
    find = browser.find_element
    wait_for(lambda: find(By.ID, 'status').text == 'connected'
             and 'holonomic' in find(By.ID, 'robot').text, 30.0, what='the youBot on the page')
    assert find(By.ID, 'strafe_left').is_displayed() and find(By.ID, 'strafe_right').is_displayed()
    assert not find(By.ID, 'report_turns_option').is_displayed()

    # Strafe left: the base moves along +y in its odometry, not along x.
    strafe = find(By.ID, 'strafe_left')
    ActionChains(browser).click_and_hold(strafe).perform()
    wait_for(lambda: odom and odom[-1][1].pose.pose.position.y > 0.05, 20.0,
             what='the youBot to strafe 5 cm')
    ActionChains(browser).release(strafe).perform()
    wait_for(lambda: abs(odom[-1][1].twist.twist.linear.y) < 0.005, 20.0,
             what='the youBot to stop')
    pose = odom[-1][1].pose.pose.position
    assert pose.y > 0.05 and abs(pose.x) < 0.02 * pose.y + 0.005

    state = PipelineState(loader_state='PICK', transport_state='WAIT', status='running',
                          total=8, identified=3, picked=2, delivered=1, elapsed=12.5)
    state_pub.publish(state)
    for kind, material, color in (('seen', 4, 'purple'), ('picked', 2, 'orange'),
                                  ('delivered', 2, 'orange')):
        event = PipelineEvent(kind=kind, robot='zu12', material_id=material, color=color,
                              detail=f'{kind} detail')
        event.header.stamp.sec = 12
        event_pub.publish(event)
    wait_for(lambda: find(By.ID, 'cell').is_displayed(), 20.0, what='the pipeline section')
    wait_for(lambda: find(By.ID, 'cell_elapsed').text == '12.5'
             and len(find(By.ID, 'materials').find_elements(By.TAG_NAME, 'tr')) == 3, 20.0,
             what="the coordinator's state and two materials")
    assert find(By.ID, 'cell_loader').text == 'PICK'
    assert find(By.ID, 'cell_transport').text == 'WAIT'
    assert '3 identified, 2 picked, 1 delivered' in find(By.ID, 'cell_counts').text
    rows = [r.text for r in find(By.ID, 'materials').find_elements(By.TAG_NAME, 'tr')[1:]]
    assert rows[0].startswith('2 orange delivered zu12') and rows[1].startswith('4 purple seen')


def test_only_the_panels_own_page_may_drive(start_node):
    """A page of another site, open in the same browser, must not reach the robots: its
    WebSocket carries that site's Origin and is refused. A plain HTTP request for the page, a
    request for anything else and a message that is not a command get what they should."""
    import asyncio
    import json
    import urllib.request

    import websockets
    from websockets.exceptions import InvalidStatus

    start_node('sim_node')
    panel = start_node('control_panel', '-p', 'port:=0')
    wait_for(lambda: re.search(r'on (http://127\.0\.0\.1:\d+/)', panel.output())
             or not panel.alive(), 30.0, what='the panel to serve')
    url = re.search(r'on (http://127\.0\.0\.1:\d+/)', panel.output()).group(1)
    with urllib.request.urlopen(url) as page:
        assert page.status == 200 and b'Control panel' in page.read()
    with pytest.raises(urllib.error.HTTPError, match='404'):
        urllib.request.urlopen(url + 'etc/passwd')
    ws_url = url.replace('http', 'ws') + 'ws'

    async def session():
        with pytest.raises(InvalidStatus, match='403'):
            async with websockets.connect(ws_url, origin='http://evil.example'):
                pass
        async with websockets.connect(ws_url, origin=url.rstrip('/')) as ws:
            hello = json.loads(await ws.recv())
            assert hello['op'] == 'hello'
            await ws.send('{"op": "hold", "motion": "fly"}')
            while True:
                reply = json.loads(await ws.recv())
                if reply['op'] == 'refused':
                    return reply['text']

    assert 'unknown motion' in asyncio.run(session())
    assert 'refused a WebSocket from the page of http://evil.example' in panel.output()
    assert panel.alive()
