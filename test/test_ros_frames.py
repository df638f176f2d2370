"""TF and URDF on the node: every frame id the node publishes is in the TF tree at that
stamp, /tf follows /joint_states, the URDF on robot_description parses and names the
/joint_states joints, and two nodes with their own prefixes and namespaces coexist."""
import io

import pytest
import yourdfpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from geometry_msgs.msg import WrenchStamped
from gripper_sim_interfaces.msg import FruitState
from visualization_msgs.msg import MarkerArray

from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(7)
GRIPPERS = {'/a': 'g1/', '/b': 'g2/'}   # namespace -> frame_prefix
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
DEEP = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
HEADED = {'fruit/nodes': PointCloud2, 'fruit/state': FruitState,
          'left_jaw/wrench': WrenchStamped, 'right_jaw/wrench': WrenchStamped,
          'markers': MarkerArray}


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class Listener:
    """Everything the two nodes publish that names a frame, with its stamp."""

    def __init__(self, node):
        self.tf: dict[int, dict[str, tuple]] = {}    # stamp -> child -> (parent, xyz)
        self.static: dict[str, tuple] = {}
        self.descriptions: dict[str, str] = {}
        self.joint_states: dict[str, dict[int, JointState]] = {ns: {} for ns in GRIPPERS}
        self.used: list[tuple[str, str, int]] = []   # (topic, frame id, stamp ns)
        node.create_subscription(TFMessage, '/tf', self._on_tf, DEEP)
        node.create_subscription(TFMessage, '/tf_static', self._on_static, LATCHED)
        for ns in GRIPPERS:
            node.create_subscription(String, f'{ns}/robot_description',
                                     lambda msg, ns=ns: self.descriptions.update({ns: msg.data}),
                                     LATCHED)
            node.create_subscription(
                JointState, f'{ns}/joint_states',
                lambda msg, ns=ns: self.joint_states[ns].update({_ns(msg.header.stamp): msg}),
                DEEP)
            for suffix, kind in HEADED.items():
                topic = f'{ns}/gripper_sim/{suffix}'
                node.create_subscription(kind, topic,
                                         lambda msg, topic=topic: self._on_headed(topic, msg),
                                         DEEP)

    @staticmethod
    def _edges(msg):
        for t in msg.transforms:
            v = t.transform.translation
            yield t, (t.header.frame_id, (v.x, v.y, v.z))

    def _on_tf(self, msg):
        for t, edge in self._edges(msg):
            self.tf.setdefault(_ns(t.header.stamp), {})[t.child_frame_id] = edge

    def _on_static(self, msg):
        for t, edge in self._edges(msg):
            self.static[t.child_frame_id] = edge

    def _on_headed(self, topic, msg):
        headers = [m.header for m in msg.markers] if hasattr(msg, 'markers') else [msg.header]
        self.used.extend((topic, h.frame_id, _ns(h.stamp)) for h in headers)

    def ready(self, batches: int) -> bool:
        return (len(self.descriptions) == len(GRIPPERS) and len(self.tf) >= batches
                and all(len(states) >= batches for states in self.joint_states.values())
                and {p for p in GRIPPERS.values()} <= {c.split('/')[0] + '/'
                                                      for c in self.static})

    def chain(self, frame: str, stamp: int) -> list[str]:
        """The frames from ``frame`` up to ``world`` at ``stamp``; AssertionError if the
        tree at that stamp does not reach ``world``."""
        moving = self.tf.get(stamp, {})
        path = [frame]
        while frame != 'world':
            edge = self.static.get(frame) or moving.get(frame)
            assert edge is not None, f"frame '{frame}' not in the TF tree at {stamp} ns"
            frame = edge[0]
            path.append(frame)
            assert len(path) < 20, path
        return path

    def position(self, frame: str, stamp: int) -> tuple[float, float, float]:
        moving = self.tf[stamp]
        xyz = [0.0, 0.0, 0.0]
        while frame != 'world':
            parent, step = self.static.get(frame) or moving[frame]
            xyz = [a + b for a, b in zip(xyz, step)]
            frame = parent
        return tuple(xyz)


@pytest.fixture(scope='module')
def two_grippers(tmp_path_factory, node_and_client):
    logs = tmp_path_factory.mktemp('frames')
    parameters = {'publish_rate': 20.0, 'real_time_factor': 1.0}
    with node_and_client({**parameters, 'frame_prefix': 'g1/'}, DOMAIN, logs / 'a.log',
                         extra=['-r', '__ns:=/a'], node_path='/a/gripper_sim') as (pa, client):
        with node_and_client({**parameters, 'frame_prefix': 'g2/', 'publish_clock': False},
                             DOMAIN, logs / 'b.log', client_name='frames_client_b',
                             extra=['-r', '__ns:=/b'], node_path='/b/gripper_sim') as (pb, _):
            listener = Listener(client.node)
            client.publish('gap', 0.03)   # closes gripper a: its jaw frames move
            client.spin_until(lambda: listener.ready(20), 120, 'frames from both nodes')
            yield pa, pb, client, listener


def test_every_published_frame_id_is_in_the_tf_tree_at_its_stamp(two_grippers):
    _, _, _, listener = two_grippers
    checked = 0
    for topic, frame, stamp in listener.used:
        if stamp not in listener.tf:
            continue   # that batch's /tf has not arrived yet
        namespace = topic.split('/')[1]
        prefix = GRIPPERS['/' + namespace]
        assert frame.startswith(prefix), (topic, frame)
        assert listener.chain(frame, stamp)[-1] == 'world'
        checked += 1
    topics = {topic for topic, *_ in listener.used}
    assert len(topics) == 2 * len(HEADED) and checked >= 2 * len(HEADED)


def test_tf_follows_the_joint_states(two_grippers):
    _, _, _, listener = two_grippers
    compared = 0
    gaps = []
    for stamp, state in listener.joint_states['/a'].items():
        if stamp not in listener.tf or 'g1/left_jaw' not in listener.tf[stamp]:
            continue
        q = dict(zip(state.name, state.position))
        base = listener.position('g1/gripper_base', stamp)
        left = listener.position('g1/left_jaw', stamp)
        right = listener.position('g1/right_jaw', stamp)
        assert base == pytest.approx((q['transport_joint'], 0.0, q['lift_joint']), abs=1e-9)
        assert abs(left[0] - base[0]) == pytest.approx(q['left_jaw_joint'], abs=1e-9)
        assert abs(right[0] - base[0]) == pytest.approx(q['right_jaw_joint'], abs=1e-9)
        assert left[2] == right[2] == pytest.approx(q['lift_joint'], abs=1e-9)
        gaps.append(right[0] - left[0])
        compared += 1
    assert compared >= 5
    assert max(gaps) - min(gaps) > 1e-3   # the jaws moved, and their frames with them


def test_the_urdf_parses_and_names_the_joint_states_joints(two_grippers):
    _, _, _, listener = two_grippers
    for ns, prefix in GRIPPERS.items():
        model = yourdfpy.URDF.load(io.StringIO(listener.descriptions[ns]),
                                   build_collision_scene_graph=False, load_meshes=False)
        assert model.validate()
        state = next(iter(listener.joint_states[ns].values()))
        assert sorted(model.actuated_joint_names) == sorted(state.name)
        assert len(state.name) == len(state.position) == len(state.velocity) \
            == len(state.effort)
        links = {link.name for link in model.robot.links}
        published = set(listener.static) | {'world'}
        published |= {child for edges in listener.tf.values() for child in edges}
        assert links - {'world'} and all(link.startswith(prefix) for link in links - {'world'})
        assert links <= published


def test_two_prefixed_nodes_share_only_the_world(two_grippers):
    pa, pb, _, listener = two_grippers
    assert pa.running and pb.running
    frames = set(listener.static) | {c for edges in listener.tf.values() for c in edges}
    mine = {prefix: {f for f in frames if f.startswith(prefix)} for prefix in GRIPPERS.values()}
    assert mine['g1/'] and mine['g2/'] and not mine['g1/'] & mine['g2/']
    assert frames == mine['g1/'] | mine['g2/']
    assert {f[len('g1/'):] for f in mine['g1/']} == {f[len('g2/'):] for f in mine['g2/']}
    parents = {edge[0] for edges in listener.tf.values() for edge in edges.values()}
    parents |= {edge[0] for edge in listener.static.values()}
    assert parents <= frames | {'world'}


def test_a_bad_frame_prefix_stops_the_node_with_a_message(tmp_path):
    process = node_process({'frame_prefix': '/g1'}, env=ros_environment(DOMAIN),
                           log_path=tmp_path / 'bad.log')
    process.start()
    try:
        process.process.wait(120)
    finally:
        process.stop()
    assert process.process.returncode == 2
    log = process.log()
    assert "frame_prefix '/g1' is not valid" in log and 'Traceback' not in log
