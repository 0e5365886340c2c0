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
//   fastdds-peer --domain D sim-cell --table FILE --dh d1 a2 a3 d4 d5 d6 --image W H
//       --camera-info ... [--tf-static ...] [--action NAME] [--abort-goal N]
//       a simulated UR arm and camera, the way the UR driver and a camera node would serve them:
//       the topics of `stream`, and the control_msgs/FollowJointTrajectory action on NAME
//       (default /scaled_joint_trajectory_controller/follow_joint_trajectory) as rmw_fastrtps
//       serves it. FILE (written by the test) holds the start joints and, for every rendered
//       view, the flange position there, its base_link -> tool0 transform and its frame's pixels;
//       at the end of a goal, the view whose flange position the forward kinematics (the DH
//       parameters) reaches is shown. Every goal, arrival, cancel and fault is one JSON line on
//       stdout (the events of scripts/ros2-peer.py sim-cell). --abort-goal N: the Nth goal ends
//       ABORTED with PATH_TOLERANCE_VIOLATED halfway.
//
// Always on the loopback interface only: UDPv4 on 127.0.0.1, discovery by unicast to the
// well-known ports of participant ids 0..9 on 127.0.0.1. `--shm` adds Fast DDS's shared memory
// transport beside it, as a default Fast DDS node has (only another Fast DDS process can use it).

#include "peer.hpp"

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

static int stream(DomainParticipant* p, Args& a)
{
    Stream s;
    while (a.more())
    {
        std::string o = a.next("option");
        if (!stream_option(s, o, a))
        {
            die("stream: unknown option " + o);
        }
    }
    Publisher* pub = p->create_publisher(PUBLISHER_QOS_DEFAULT);
    auto [tf_w, static_w, joints_w, image_w, info_w] = driver_writers(p, pub);

    write_static(static_w, s.tf_static);
    sen::Image_ image = mono8_image(s.width, s.height);
    image.data().resize(static_cast<size_t>(s.width) * s.height);
    for (uint32_t y = 0; y < s.height; ++y)
    {
        for (uint32_t x = 0; x < s.width; ++x)
        {
            image.data()[static_cast<size_t>(y) * s.width + x] = static_cast<uint8_t>((x + 3 * y) % 251);
        }
    }
    sen::CameraInfo_ info = camera_info_of(s);

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
    else if (command == "sim-cell")
    {
        rc = sim_cell(p, a);
    }
    else
    {
        die("usage: fastdds-peer --domain D [--shm] (tf-static|stream|sim-cell) ...");
    }
    p->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(p);
    return rc;
}
