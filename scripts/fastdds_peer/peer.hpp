// The Fast DDS peer's shared half (see peer.cpp for what it is and its commands): the
// participant on the loopback interface, ROS 2 topics and their QoS, the command line, message
// helpers, and the driver topics that `stream` and `sim-cell` both publish.

#pragma once


#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <type_traits>
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

[[noreturn]] inline void die(const std::string& why)
{
    std::fprintf(stderr, "fastdds-peer: %s\n", why.c_str());
    std::exit(2);
}

// ---- the participant -------------------------------------------------------------------------

inline DomainParticipant* loopback_participant(int domain, bool shm)
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

// A ROS 2 topic of type T, the type registered under its DDS name: `rt/<name>`, or with `prefix`
// and `suffix` a service's `rq/<name>Request` and `rr/<name>Reply`.
template<typename PubSubType>
inline Topic* ros_topic(DomainParticipant* p, const std::string& ros_name,
                        const std::string& prefix = "rt", const std::string& suffix = "")
{
    TypeSupport type(new PubSubType());
    std::string type_name = type.get_type_name();
    if (p->find_type(type_name).empty())
    {
        type.register_type(p);
    }
    std::string name = prefix + ros_name + suffix;
    Topic* t = p->create_topic(name, type_name, TOPIC_QOS_DEFAULT);
    if (t == nullptr)
    {
        die("cannot create the topic " + name);
    }
    return t;
}

enum class Qos { Latched, Reliable, Sensor };

inline DataWriterQos writer_qos(Qos q, int depth)
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

inline DataReaderQos reader_qos(Qos q, int depth)
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

inline builtin_interfaces::msg::dds_::Time_ now_stamp()
{
    auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
        std::chrono::system_clock::now().time_since_epoch()).count();
    builtin_interfaces::msg::dds_::Time_ t;
    t.sec(static_cast<int32_t>(ns / 1000000000));
    t.nanosec(static_cast<uint32_t>(ns % 1000000000));
    return t;
}

inline geo::TransformStamped_ transform_arg(Args& a)
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

inline void print_event(const std::string& json)
{
    std::printf("%s\n", json.c_str());
    std::fflush(stdout);
}

inline std::string num(double x)
{
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", x);
    return buf;
}

inline std::string quoted(const std::string& s)
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

// One of the options `stream` and `sim-cell` share; false when `o` is none of them.
inline bool stream_option(Stream& s, const std::string& o, Args& a)
{
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
        return false;
    }
    return true;
}

inline sen::CameraInfo_ camera_info_of(const Stream& s)
{
    sen::CameraInfo_ info;
    info.header().frame_id("camera_optical_frame");
    info.width(s.width);
    info.height(s.height);
    info.distortion_model("plumb_bob");
    info.d(s.d);
    info.k({s.k[0], 0, s.k[2], 0, s.k[1], s.k[3], 0, 0, 1});
    info.r({1, 0, 0, 0, 1, 0, 0, 0, 1});
    info.p({s.k[0], 0, s.k[2], 0, 0, s.k[1], s.k[3], 0, 0, 0, 1, 0});
    return info;
}

inline void write_static(DataWriter* w, std::vector<geo::TransformStamped_> transforms)
{
    if (transforms.empty())
    {
        return;
    }
    tf2::TFMessage_ msg;
    for (auto& t : transforms)
    {
        t.header().stamp(now_stamp());
        msg.transforms().push_back(t);
    }
    w->write(&msg);
}

// An empty mono8 image of the camera (`camera_optical_frame`), its pixels to be filled in.
inline sen::Image_ mono8_image(uint32_t width, uint32_t height)
{
    sen::Image_ image;
    image.header().frame_id("camera_optical_frame");
    image.width(width);
    image.height(height);
    image.encoding("mono8");
    image.is_bigendian(0);
    image.step(width);
    return image;
}

inline DataWriter* new_writer(Publisher* pub, Topic* t, Qos q, int depth)
{
    DataWriter* w = pub->create_datawriter(t, writer_qos(q, depth));
    if (w == nullptr)
    {
        die("cannot create a writer of " + t->get_name());
    }
    return w;
}

// The topics a UR driver and a camera node publish, with their publishers' QoS: tf2's
// DynamicBroadcasterQoS (reliable, keep last 100) and StaticBroadcasterQoS, a reliable
// /joint_states, sensor data QoS for the camera.
struct DriverWriters
{
    DataWriter *tf, *tf_static, *joints, *image, *info;
};

inline DriverWriters driver_writers(DomainParticipant* p, Publisher* pub)
{
    return DriverWriters{
        new_writer(pub, ros_topic<tf2::TFMessage_PubSubType>(p, "/tf"), Qos::Reliable, 100),
        new_writer(pub, ros_topic<tf2::TFMessage_PubSubType>(p, "/tf_static"), Qos::Latched, 1),
        new_writer(pub, ros_topic<sen::JointState_PubSubType>(p, "/joint_states"), Qos::Reliable, 10),
        new_writer(pub, ros_topic<sen::Image_PubSubType>(p, "/image_raw"), Qos::Sensor, 5),
        new_writer(pub, ros_topic<sen::CameraInfo_PubSubType>(p, "/camera_info"), Qos::Sensor, 5),
    };
}

// ---- the commands ----------------------------------------------------------------------------

// sim_cell.cpp
int sim_cell(DomainParticipant* p, Args& a);
