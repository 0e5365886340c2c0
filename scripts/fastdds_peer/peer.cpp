// An independent ROS 2 peer on eProsima Fast DDS (the default middleware of ROS 2 Humble and
// Jazzy), with no ROS installation: its message types are ros2_msgs.idl, turned into C++ by
// fastddsgen at build time. handeye's tests (tests/it/ros2_live/fastdds.rs) run it to check that
// handeye's pure-Rust ROS 2 node (ros2-client on RustDDS) and Fast DDS understand each other.
//
//   fastdds-peer --domain D [--shm] tf-static --expect N [--timeout S]
//       joins late, reads the latched /tf_static (reliable, transient local, keep last 1) and
//       prints its transforms as one JSON line (17 significant digits).
//   fastdds-peer --domain D [--shm] stream [--duration S] [--tf P C x y z qx qy qz qw]...
//       [--tf-static P C x y z qx qy qz qw]... [--joint NAME POS VEL]...
//       [--image W H] [--camera-info fx fy cx cy d0 d1 d2 d3 d4]
//       publishes the way ROS 2 drivers do: /tf (reliable, keep last 100) at 50 Hz, /tf_static
//       once (latched), /joint_states (reliable, keep last 10) at 100 Hz, /image_raw (mono8,
//       pixel (x, y) = (x + 3 y) mod 251) and /camera_info (sensor data QoS: best effort, keep
//       last 5) at 15 Hz. Prints {"event":"ready"} once its writers exist.
//
// Always on the loopback interface only: UDPv4 on 127.0.0.1, discovery by unicast to the
// well-known ports of participant ids 0..9 on 127.0.0.1. `--shm` adds Fast DDS's shared memory
// transport beside it, as a default Fast DDS node has (only another Fast DDS process can use it).

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include "ros2_msgsPubSubTypes.h"

using namespace eprosima::fastdds::dds;
using eprosima::fastrtps::rtps::IPLocator;
using eprosima::fastrtps::rtps::Locator_t;

namespace tf2 = tf2_msgs::msg::dds_;
namespace geo = geometry_msgs::msg::dds_;
namespace sen = sensor_msgs::msg::dds_;

[[noreturn]] static void die(const std::string& why)
{
    std::fprintf(stderr, "fastdds-peer: %s\n", why.c_str());
    std::exit(2);
}

// ---- the participant -------------------------------------------------------------------------

static DomainParticipant* loopback_participant(int domain, bool shm)
{
    DomainParticipantQos pqos = PARTICIPANT_QOS_DEFAULT;
    pqos.name("handeye_fastdds_peer");
    pqos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.emplace_back("127.0.0.1");
    pqos.transport().user_transports.push_back(udp);
    if (shm)
    {
        // As a default Fast DDS node (rmw_fastrtps) has it: shared memory offered beside UDP.
        pqos.transport().user_transports.push_back(
            std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>());
    }
    // The SPDP unicast port of participant id i on domain d: 7400 + 250 d + 10 + 2 i (RTPS 9.6.1.1).
    for (int i = 0; i < 10; ++i)
    {
        Locator_t peer;
        IPLocator::setIPv4(peer, 127, 0, 0, 1);
        peer.port = static_cast<uint32_t>(7400 + 250 * domain + 10 + 2 * i);
        pqos.wire_protocol().builtin.initialPeersList.push_back(peer);
    }
    DomainParticipant* p = DomainParticipantFactory::get_instance()->create_participant(domain, pqos);
    if (p == nullptr)
    {
        die("cannot create the participant on domain " + std::to_string(domain));
    }
    return p;
}

// A ROS 2 topic of type T: `rt/<name>`, the type registered under its DDS name.
template<typename PubSubType>
static Topic* ros_topic(DomainParticipant* p, const std::string& ros_name)
{
    TypeSupport type(new PubSubType());
    std::string type_name = type.get_type_name();
    if (p->find_type(type_name).empty())
    {
        type.register_type(p);
    }
    Topic* t = p->create_topic("rt" + ros_name, type_name, TOPIC_QOS_DEFAULT);
    if (t == nullptr)
    {
        die("cannot create the topic rt" + ros_name);
    }
    return t;
}

enum class Qos { Latched, Reliable, Sensor };

static DataWriterQos writer_qos(Qos q, int depth)
{
    DataWriterQos w = DATAWRITER_QOS_DEFAULT;
    w.history().kind = KEEP_LAST_HISTORY_QOS;
    w.history().depth = depth;
    w.reliability().kind = q == Qos::Sensor ? BEST_EFFORT_RELIABILITY_QOS : RELIABLE_RELIABILITY_QOS;
    w.durability().kind = q == Qos::Latched ? TRANSIENT_LOCAL_DURABILITY_QOS : VOLATILE_DURABILITY_QOS;
    // Large images: memory that grows with the sample (the generated type's bound is nominal).
    w.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    return w;
}

static DataReaderQos reader_qos(Qos q, int depth)
{
    DataReaderQos r = DATAREADER_QOS_DEFAULT;
    r.history().kind = KEEP_LAST_HISTORY_QOS;
    r.history().depth = depth;
    r.reliability().kind = q == Qos::Sensor ? BEST_EFFORT_RELIABILITY_QOS : RELIABLE_RELIABILITY_QOS;
    r.durability().kind = q == Qos::Latched ? TRANSIENT_LOCAL_DURABILITY_QOS : VOLATILE_DURABILITY_QOS;
    r.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    return r;
}

// ---- arguments -------------------------------------------------------------------------------

struct Args
{
    std::vector<std::string> v;
    size_t i = 0;

    bool more() const { return i < v.size(); }
    std::string next(const char* what)
    {
        if (i >= v.size())
        {
            die(std::string("missing ") + what);
        }
        return v[i++];
    }
    double number(const char* what)
    {
        std::string s = next(what);
        char* end = nullptr;
        double x = std::strtod(s.c_str(), &end);
        if (end == s.c_str() || *end != '\0')
        {
            die(std::string("not a number for ") + what + ": " + s);
        }
        return x;
    }
};

// ---- messages --------------------------------------------------------------------------------

static builtin_interfaces::msg::dds_::Time_ now_stamp()
{
    auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
        std::chrono::system_clock::now().time_since_epoch()).count();
    builtin_interfaces::msg::dds_::Time_ t;
    t.sec(static_cast<int32_t>(ns / 1000000000));
    t.nanosec(static_cast<uint32_t>(ns % 1000000000));
    return t;
}

static geo::TransformStamped_ transform_arg(Args& a)
{
    geo::TransformStamped_ t;
    t.header().frame_id(a.next("parent frame"));
    t.child_frame_id(a.next("child frame"));
    t.transform().translation().x(a.number("x"));
    t.transform().translation().y(a.number("y"));
    t.transform().translation().z(a.number("z"));
    t.transform().rotation().x(a.number("qx"));
    t.transform().rotation().y(a.number("qy"));
    t.transform().rotation().z(a.number("qz"));
    t.transform().rotation().w(a.number("qw"));
    return t;
}

static void print_event(const std::string& json)
{
    std::printf("%s\n", json.c_str());
    std::fflush(stdout);
}

static std::string num(double x)
{
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", x);
    return buf;
}

static std::string quoted(const std::string& s)
{
    std::string out = "\"";
    for (char c : s)
    {
        if (c == '"' || c == '\\')
        {
            out += '\\';
        }
        out += c;
    }
    return out + "\"";
}

// ---- tf-static: the late joiner --------------------------------------------------------------

static int tf_static(DomainParticipant* p, Args& a)
{
    size_t expect = 1;
    double timeout = 30;
    while (a.more())
    {
        std::string o = a.next("option");
        if (o == "--expect")
        {
            expect = static_cast<size_t>(a.number("--expect"));
        }
        else if (o == "--timeout")
        {
            timeout = a.number("--timeout");
        }
        else
        {
            die("tf-static: unknown option " + o);
        }
    }
    Topic* topic = ros_topic<tf2::TFMessage_PubSubType>(p, "/tf_static");
    Subscriber* sub = p->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    // tf2's StaticListenerQoS: reliable, transient local (the writer keeps the last message).
    DataReader* reader = sub->create_datareader(topic, reader_qos(Qos::Latched, 1));
    if (reader == nullptr)
    {
        die("cannot create the /tf_static reader");
    }
    auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout);
    while (std::chrono::steady_clock::now() < end)
    {
        reader->wait_for_unread_message(eprosima::fastrtps::Duration_t(0, 100000000));
        tf2::TFMessage_ msg;
        SampleInfo info;
        while (reader->take_next_sample(&msg, &info) == ReturnCode_t::RETCODE_OK)
        {
            if (!info.valid_data || msg.transforms().size() < expect)
            {
                continue;
            }
            std::string out = "{\"transforms\":[";
            for (size_t k = 0; k < msg.transforms().size(); ++k)
            {
                const geo::TransformStamped_& t = msg.transforms()[k];
                const auto& v = t.transform().translation();
                const auto& q = t.transform().rotation();
                out += (k ? "," : "");
                out += "{\"parent\":" + quoted(t.header().frame_id()) + ",\"child\":" +
                        quoted(t.child_frame_id()) + ",\"stamp\":[" +
                        std::to_string(t.header().stamp().sec()) + "," +
                        std::to_string(t.header().stamp().nanosec()) + "],\"translation\":[" +
                        num(v.x()) + "," + num(v.y()) + "," + num(v.z()) + "],\"quaternion_xyzw\":[" +
                        num(q.x()) + "," + num(q.y()) + "," + num(q.z()) + "," + num(q.w()) + "]}";
            }
            print_event(out + "]}");
            return 0;
        }
    }
    std::fprintf(stderr, "fastdds-peer: no /tf_static message with %zu transforms within %.0f s\n",
            expect, timeout);
    return 1;
}

// ---- stream: a driver's topics ---------------------------------------------------------------

struct Stream
{
    std::vector<geo::TransformStamped_> tf, tf_static;
    std::vector<std::string> joint_names;
    std::vector<double> joint_positions, joint_speeds;
    uint32_t width = 0, height = 0;
    bool camera_info = false;
    double k[4] = {0, 0, 0, 0};
    std::vector<double> d;
    double duration = 3600;
};

static int stream(DomainParticipant* p, Args& a)
{
    Stream s;
    while (a.more())
    {
        std::string o = a.next("option");
        if (o == "--tf")
        {
            s.tf.push_back(transform_arg(a));
        }
        else if (o == "--tf-static")
        {
            s.tf_static.push_back(transform_arg(a));
        }
        else if (o == "--joint")
        {
            s.joint_names.push_back(a.next("joint name"));
            s.joint_positions.push_back(a.number("joint position"));
            s.joint_speeds.push_back(a.number("joint speed"));
        }
        else if (o == "--image")
        {
            s.width = static_cast<uint32_t>(a.number("width"));
            s.height = static_cast<uint32_t>(a.number("height"));
        }
        else if (o == "--camera-info")
        {
            s.camera_info = true;
            for (double& x : s.k)
            {
                x = a.number("fx fy cx cy");
            }
            for (int j = 0; j < 5; ++j)
            {
                s.d.push_back(a.number("d0..d4"));
            }
        }
        else if (o == "--duration")
        {
            s.duration = a.number("--duration");
        }
        else
        {
            die("stream: unknown option " + o);
        }
    }
    Publisher* pub = p->create_publisher(PUBLISHER_QOS_DEFAULT);
    auto writer = [&](Topic* t, Qos q, int depth) {
        DataWriter* w = pub->create_datawriter(t, writer_qos(q, depth));
        if (w == nullptr)
        {
            die("cannot create a writer of " + t->get_name());
        }
        return w;
    };
    // tf2's DynamicBroadcasterQoS (reliable, keep last 100) and StaticBroadcasterQoS.
    DataWriter* tf_w = writer(ros_topic<tf2::TFMessage_PubSubType>(p, "/tf"), Qos::Reliable, 100);
    DataWriter* static_w = writer(ros_topic<tf2::TFMessage_PubSubType>(p, "/tf_static"), Qos::Latched, 1);
    DataWriter* joints_w = writer(ros_topic<sen::JointState_PubSubType>(p, "/joint_states"), Qos::Reliable, 10);
    DataWriter* image_w = writer(ros_topic<sen::Image_PubSubType>(p, "/image_raw"), Qos::Sensor, 5);
    DataWriter* info_w = writer(ros_topic<sen::CameraInfo_PubSubType>(p, "/camera_info"), Qos::Sensor, 5);

    if (!s.tf_static.empty())
    {
        tf2::TFMessage_ msg;
        for (auto& t : s.tf_static)
        {
            t.header().stamp(now_stamp());
            msg.transforms().push_back(t);
        }
        static_w->write(&msg);
    }
    sen::Image_ image;
    image.header().frame_id("camera_optical_frame");
    image.width(s.width);
    image.height(s.height);
    image.encoding("mono8");
    image.is_bigendian(0);
    image.step(s.width);
    image.data().resize(static_cast<size_t>(s.width) * s.height);
    for (uint32_t y = 0; y < s.height; ++y)
    {
        for (uint32_t x = 0; x < s.width; ++x)
        {
            image.data()[static_cast<size_t>(y) * s.width + x] = static_cast<uint8_t>((x + 3 * y) % 251);
        }
    }
    sen::CameraInfo_ info;
    info.header().frame_id("camera_optical_frame");
    info.width(s.width);
    info.height(s.height);
    info.distortion_model("plumb_bob");
    info.d(s.d);
    info.k({s.k[0], 0, s.k[2], 0, s.k[1], s.k[3], 0, 0, 1});
    info.r({1, 0, 0, 0, 1, 0, 0, 0, 1});
    info.p({s.k[0], 0, s.k[2], 0, 0, s.k[1], s.k[3], 0, 0, 0, 1, 0});

    print_event("{\"event\":\"ready\"}");
    auto start = std::chrono::steady_clock::now();
    auto end = start + std::chrono::duration<double>(s.duration);
    for (uint64_t tick = 0; std::chrono::steady_clock::now() < end; ++tick)
    {
        // 100 Hz: joints every tick, TF every 2nd, the camera every 7th (~14 Hz).
        if (!s.joint_names.empty())
        {
            sen::JointState_ js;
            js.header().stamp(now_stamp());
            js.name(s.joint_names);
            js.position(s.joint_positions);
            js.velocity(s.joint_speeds);
            joints_w->write(&js);
        }
        if (!s.tf.empty() && tick % 2 == 0)
        {
            tf2::TFMessage_ msg;
            for (auto t : s.tf)
            {
                t.header().stamp(now_stamp());
                msg.transforms().push_back(t);
            }
            tf_w->write(&msg);
        }
        if (s.width > 0 && tick % 7 == 0)
        {
            image.header().stamp(now_stamp());
            image_w->write(&image);
            if (s.camera_info)
            {
                info.header().stamp(image.header().stamp());
                info_w->write(&info);
            }
        }
        std::this_thread::sleep_until(start + std::chrono::milliseconds(10 * (tick + 1)));
    }
    return 0;
}

int main(int argc, char** argv)
{
    Args a;
    a.v.assign(argv + 1, argv + argc);
    int domain = 0;
    bool shm = false;
    std::string command;
    while (a.more())
    {
        std::string o = a.next("command");
        if (o == "--domain")
        {
            domain = static_cast<int>(a.number("--domain"));
        }
        else if (o == "--shm")
        {
            shm = true;
        }
        else
        {
            command = o;
            break;
        }
    }
    DomainParticipant* p = loopback_participant(domain, shm);
    int rc = 2;
    if (command == "tf-static")
    {
        rc = tf_static(p, a);
    }
    else if (command == "stream")
    {
        rc = stream(p, a);
    }
    else
    {
        die("usage: fastdds-peer --domain D [--shm] (tf-static|stream) ...");
    }
    p->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(p);
    return rc;
}
