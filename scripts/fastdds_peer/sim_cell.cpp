// The Fast DDS peer's `sim-cell` (see peer.cpp): a simulated UR arm and camera, served the way
// the UR driver and a camera node would, with the FollowJointTrajectory action as rmw_fastrtps
// serves it.

#include "peer.hpp"

// ---- sim-cell: an arm driven by FollowJointTrajectory goals, and its camera -----------------

namespace act = control_msgs::action::dds_;
using eprosima::fastrtps::rtps::SampleIdentity;
using eprosima::fastrtps::rtps::WriteParams;
using Joints = std::array<double, 6>;

// A pose of the table: the start's joints or a view's flange position in the arm's base frame
// (where the forward kinematics must put the flange), the /tf transform base_link -> tool0
// there, and the frame the camera shows there (none: a grey frame).
struct TablePose
{
    Joints q{};
    double position[3] = {0, 0, 0};
    geo::Transform_ flange;
    std::vector<uint8_t> pixels;
};

// The flange position of a UR arm at joints q, by its DH parameters (d1, a2, a3, d4, d5, d6;
// alpha = pi/2, 0, 0, pi/2, -pi/2, 0): the product of Rz(q) Tz(d) Tx(a) Rx(alpha) per link.
static std::array<double, 3> ur_flange_position(const double dh[6], const Joints& q)
{
    const double d[6] = {dh[0], 0, 0, dh[3], dh[4], dh[5]};
    const double a[6] = {0, dh[1], dh[2], 0, 0, 0};
    const double alpha[6] = {M_PI / 2, 0, 0, M_PI / 2, -M_PI / 2, 0};
    double T[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
    for (int i = 0; i < 6; ++i)
    {
        double ct = std::cos(q[i]), st = std::sin(q[i]), ca = std::cos(alpha[i]), sa = std::sin(alpha[i]);
        double L[4][4] = {{ct, -st * ca, st * sa, a[i] * ct},
                          {st, ct * ca, -ct * sa, a[i] * st},
                          {0, sa, ca, d[i]},
                          {0, 0, 0, 1}};
        double R[4][4];
        for (int r = 0; r < 4; ++r)
        {
            for (int c = 0; c < 4; ++c)
            {
                R[r][c] = 0;
                for (int k = 0; k < 4; ++k)
                {
                    R[r][c] += T[r][k] * L[k][c];
                }
            }
        }
        std::memcpy(T, R, sizeof T);
    }
    return {T[0][3], T[1][3], T[2][3]};
}

struct Goal
{
    std::array<uint8_t, 16> id;
    int n = 0;
    std::vector<std::pair<double, Joints>> points; // (time from start, positions)
    std::chrono::steady_clock::time_point start;
    Joints from;
    uint8_t status = 2; // action_msgs/GoalStatus: EXECUTING 2, SUCCEEDED 4, CANCELED 5, ABORTED 6
    int32_t code = 0;
    std::string text;
    std::vector<SampleIdentity> waiting; // get_result requests answered when it ends
};

// The id a reply names its request by, as rmw_fastrtps's services take it: the request's sample
// identity (its writer's GUID and sequence number), the GUID replaced by the client's reply
// reader when the request names one in its related sample identity (rmw_fastrtps clients do;
// the reply then goes to that reader).
static SampleIdentity request_id(const SampleInfo& si)
{
    SampleIdentity id = si.sample_identity;
    if (si.related_sample_identity.writer_guid() != eprosima::fastrtps::rtps::GUID_t::unknown())
    {
        id.writer_guid() = si.related_sample_identity.writer_guid();
    }
    return id;
}

static std::string json_joints(const Joints& q)
{
    std::string out = "[";
    for (size_t i = 0; i < 6; ++i)
    {
        out += (i ? "," : "") + num(q[i]);
    }
    return out + "]";
}

// The table: one `start q1..q6 x y z qx qy qz qw` line, then `view X Y Z x y z qx qy qz qw
// PIXELS` lines (radians, metres; PIXELS a file of width x height mono8 bytes).
static std::vector<TablePose> read_table(const std::string& path, size_t frame_bytes)
{
    std::FILE* f = std::fopen(path.c_str(), "r");
    if (f == nullptr)
    {
        die("cannot read the table " + path);
    }
    std::vector<TablePose> rows;
    char kind[16];
    while (std::fscanf(f, "%15s", kind) == 1)
    {
        TablePose row;
        bool view = std::string(kind) == "view";
        double v[7];
        for (size_t i = 0; i < (view ? 3 : 6); ++i)
        {
            if (std::fscanf(f, "%lf", view ? &row.position[i] : &row.q[i]) != 1)
            {
                die("the table's joints or position");
            }
        }
        for (double& x : v)
        {
            if (std::fscanf(f, "%lf", &x) != 1)
            {
                die("the table's transform");
            }
        }
        row.flange.translation().x(v[0]);
        row.flange.translation().y(v[1]);
        row.flange.translation().z(v[2]);
        row.flange.rotation().x(v[3]);
        row.flange.rotation().y(v[4]);
        row.flange.rotation().z(v[5]);
        row.flange.rotation().w(v[6]);
        if (view)
        {
            char file[4096];
            if (std::fscanf(f, "%4095s", file) != 1)
            {
                die("the table's pixel file");
            }
            std::FILE* px = std::fopen(file, "rb");
            row.pixels.resize(frame_bytes);
            if (px == nullptr || std::fread(row.pixels.data(), 1, frame_bytes, px) != frame_bytes)
            {
                die(std::string("cannot read ") + std::to_string(frame_bytes) + " bytes from " + file);
            }
            std::fclose(px);
        }
        else if (std::string(kind) != "start" || !rows.empty())
        {
            die("the table starts with one `start` line, then `view` lines");
        }
        rows.push_back(std::move(row));
    }
    std::fclose(f);
    if (rows.empty())
    {
        die("the table is empty");
    }
    return rows;
}

int sim_cell(DomainParticipant* p, Args& a)
{
    Stream s;
    std::string table_path;
    std::string action = "/scaled_joint_trajectory_controller/follow_joint_trajectory";
    std::vector<std::string> names = {"shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                      "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"};
    int abort_goal = 0;
    double dh[6] = {0, 0, 0, 0, 0, 0};
    while (a.more())
    {
        std::string o = a.next("option");
        if (o == "--dh")
        {
            for (double& x : dh)
            {
                x = a.number("--dh d1 a2 a3 d4 d5 d6");
            }
        }
        else if (o == "--table")
        {
            table_path = a.next("--table");
        }
        else if (o == "--action")
        {
            action = a.next("--action");
        }
        else if (o == "--abort-goal")
        {
            abort_goal = static_cast<int>(a.number("--abort-goal"));
        }
        else if (!stream_option(s, o, a))
        {
            die("sim-cell: unknown option " + o);
        }
    }
    if (s.width == 0 || table_path.empty() || dh[0] == 0)
    {
        die("sim-cell needs --table, --dh and --image");
    }
    const size_t frame_bytes = static_cast<size_t>(s.width) * s.height;
    std::vector<TablePose> table = read_table(table_path, frame_bytes);

    Publisher* pub = p->create_publisher(PUBLISHER_QOS_DEFAULT);
    Subscriber* sub = p->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    auto writer = [&](Topic* t, Qos q, int depth) { return new_writer(pub, t, q, depth); };
    auto reader = [&](Topic* t) {
        DataReader* r = sub->create_datareader(t, reader_qos(Qos::Reliable, 100));
        if (r == nullptr)
        {
            die("cannot create a reader of " + t->get_name());
        }
        return r;
    };
    auto [tf_w, static_w, joints_w, image_w, info_w] = driver_writers(p, pub);
    // The action's services as rmw_fastrtps names them: rq/<action>/_action/<service>Request and
    // rr/...Reply, the request's id being the sample identity of its DDS write (no header in the
    // payload); a reply carries it back as its related sample identity.
    auto service = [&](const char* name) { return action + "/_action/" + name; };
    DataReader* goal_r = reader(ros_topic<act::FollowJointTrajectory_SendGoal_Request_PubSubType>(p, service("send_goal"), "rq", "Request"));
    DataWriter* goal_w = writer(ros_topic<act::FollowJointTrajectory_SendGoal_Response_PubSubType>(p, service("send_goal"), "rr", "Reply"), Qos::Reliable, 100);
    DataReader* result_r = reader(ros_topic<act::FollowJointTrajectory_GetResult_Request_PubSubType>(p, service("get_result"), "rq", "Request"));
    DataWriter* result_w = writer(ros_topic<act::FollowJointTrajectory_GetResult_Response_PubSubType>(p, service("get_result"), "rr", "Reply"), Qos::Reliable, 100);
    DataReader* cancel_r = reader(ros_topic<action_msgs::srv::dds_::CancelGoal_Request_PubSubType>(p, service("cancel_goal"), "rq", "Request"));
    DataWriter* cancel_w = writer(ros_topic<action_msgs::srv::dds_::CancelGoal_Response_PubSubType>(p, service("cancel_goal"), "rr", "Reply"), Qos::Reliable, 100);

    write_static(static_w, s.tf_static);
    sen::CameraInfo_ info = camera_info_of(s);
    sen::Image_ image = mono8_image(s.width, s.height);
    const std::vector<uint8_t> grey(frame_bytes, 128);

    Joints q = table[0].q, qd{};
    const TablePose* at = &table[0]; // the table pose the arm stands at (its TF and frame)
    std::vector<Goal> goals;
    Goal* running = nullptr;
    int goal_count = 0;

    auto reply_result = [&](const Goal& g, const SampleIdentity& to) {
        act::FollowJointTrajectory_GetResult_Response_ r;
        r.status(g.status);
        r.result().error_code(g.code);
        r.result().error_string(g.text);
        WriteParams wp;
        wp.related_sample_identity(to);
        result_w->write(&r, wp);
    };
    auto finish = [&](Goal& g, uint8_t status, int32_t code, const std::string& text) {
        g.status = status;
        g.code = code;
        g.text = text;
        for (const SampleIdentity& to : g.waiting)
        {
            reply_result(g, to);
        }
        g.waiting.clear();
    };
    auto find_goal = [&](const std::array<uint8_t, 16>& id) -> Goal* {
        for (Goal& g : goals)
        {
            if (g.id == id)
            {
                return &g;
            }
        }
        return nullptr;
    };
    auto serve = [&]() {
        act::FollowJointTrajectory_SendGoal_Request_ req;
        SampleInfo si;
        while (goal_r->take_next_sample(&req, &si) == ReturnCode_t::RETCODE_OK)
        {
            if (!si.valid_data)
            {
                continue;
            }
            const auto& tr = req.goal().trajectory();
            bool ok = tr.joint_names() == names && !tr.points().empty() && running == nullptr;
            double max_speed = 0;
            Goal g;
            g.id = req.goal_id().uuid();
            g.n = ++goal_count;
            for (const auto& pt : tr.points())
            {
                ok = ok && pt.positions().size() == 6;
                for (double v : pt.velocities())
                {
                    max_speed = std::max(max_speed, std::fabs(v));
                }
                if (pt.positions().size() == 6)
                {
                    Joints j;
                    std::copy(pt.positions().begin(), pt.positions().end(), j.begin());
                    g.points.emplace_back(pt.time_from_start().sec() + pt.time_from_start().nanosec() * 1e-9, j);
                }
            }
            act::FollowJointTrajectory_SendGoal_Response_ rep;
            rep.accepted(ok);
            rep.stamp(now_stamp());
            WriteParams wp;
            wp.related_sample_identity(request_id(si));
            goal_w->write(&rep, wp);
            print_event("{\"event\":\"goal\",\"n\":" + std::to_string(g.n) + ",\"accepted\":" +
                    (ok ? "true" : "false") + ",\"points\":" + std::to_string(tr.points().size()) +
                    ",\"duration_s\":" + num(g.points.empty() ? 0.0 : g.points.back().first) +
                    ",\"max_joint_speed_rad_s\":" + num(max_speed) + ",\"reply_reader_named\":" +
                    (si.related_sample_identity.writer_guid() != eprosima::fastrtps::rtps::GUID_t::unknown() ? "true" : "false") + "}");
            if (ok)
            {
                g.start = std::chrono::steady_clock::now();
                g.from = q;
                goals.push_back(std::move(g));
                running = &goals.back();
            }
        }
        act::FollowJointTrajectory_GetResult_Request_ rreq;
        while (result_r->take_next_sample(&rreq, &si) == ReturnCode_t::RETCODE_OK)
        {
            if (!si.valid_data)
            {
                continue;
            }
            Goal* g = find_goal(rreq.goal_id().uuid());
            if (g == nullptr)
            {
                Goal unknown;
                unknown.status = 0;
                unknown.code = -1;
                unknown.text = "unknown goal";
                reply_result(unknown, request_id(si));
            }
            else if (g->status >= 4)
            {
                reply_result(*g, request_id(si));
            }
            else
            {
                g->waiting.push_back(request_id(si));
            }
        }
        action_msgs::srv::dds_::CancelGoal_Request_ creq;
        while (cancel_r->take_next_sample(&creq, &si) == ReturnCode_t::RETCODE_OK)
        {
            if (!si.valid_data)
            {
                continue;
            }
            const auto& id = creq.goal_info().goal_id().uuid();
            bool any = std::all_of(id.begin(), id.end(), [](uint8_t b) { return b == 0; });
            action_msgs::srv::dds_::CancelGoal_Response_ rep;
            rep.return_code(2); // UNKNOWN_GOAL_ID
            if (running != nullptr && (any || running->id == id))
            {
                action_msgs::msg::dds_::GoalInfo_ gi;
                gi.goal_id().uuid(running->id);
                gi.stamp(now_stamp());
                rep.goals_canceling().push_back(gi);
                rep.return_code(0);
                qd = Joints{};
                print_event("{\"event\":\"cancel\",\"n\":" + std::to_string(running->n) + ",\"joints\":" + json_joints(q) + "}");
                finish(*running, 5, 0, "canceled");
                running = nullptr;
            }
            WriteParams wp;
            wp.related_sample_identity(request_id(si));
            cancel_w->write(&rep, wp);
        }
    };
    // Moves the arm along the running goal: linear between waypoints, as a controller would.
    auto step = [&](std::chrono::steady_clock::time_point now) {
        if (running == nullptr)
        {
            return;
        }
        Goal& g = *running;
        double t = std::chrono::duration<double>(now - g.start).count();
        double total = g.points.back().first;
        if (abort_goal == g.n && t > total / 2)
        {
            qd = Joints{};
            print_event("{\"event\":\"abort\",\"n\":" + std::to_string(g.n) + "}");
            finish(g, 6, -4, "simulated: path tolerance violated at joint shoulder_lift_joint");
            running = nullptr;
            return;
        }
        if (t >= total)
        {
            q = g.points.back().second;
            qd = Joints{};
            // The view whose flange position the forward kinematics reaches (within 1 mm): the
            // joints handeye's inverse kinematics chose need not be the recorded ones.
            const TablePose* found = nullptr;
            double best = 1e9;
            std::array<double, 3> x = ur_flange_position(dh, q);
            for (size_t k = 1; k < table.size(); ++k)
            {
                const double* p = table[k].position;
                double d = std::sqrt((p[0] - x[0]) * (p[0] - x[0]) + (p[1] - x[1]) * (p[1] - x[1]) +
                        (p[2] - x[2]) * (p[2] - x[2]));
                if (d < best)
                {
                    best = d;
                    found = &table[k];
                }
            }
            if (best > 1e-3)
            {
                print_event("{\"event\":\"no_view\",\"joints\":" + json_joints(q) + ",\"distance_m\":" + num(best) + "}");
            }
            else
            {
                at = found;
            }
            finish(g, 4, 0, "");
            print_event("{\"event\":\"arrived\",\"n\":" + std::to_string(g.n) + "}");
            running = nullptr;
            return;
        }
        double prev_t = 0;
        Joints prev_q = g.from;
        for (const auto& [tk, qk] : g.points)
        {
            if (t <= tk)
            {
                double span = std::max(tk - prev_t, 1e-9);
                double f = (t - prev_t) / span;
                for (size_t i = 0; i < 6; ++i)
                {
                    q[i] = prev_q[i] + f * (qk[i] - prev_q[i]);
                    qd[i] = (qk[i] - prev_q[i]) / span;
                }
                break;
            }
            prev_t = tk;
            prev_q = qk;
        }
    };

    print_event("{\"event\":\"ready\",\"poses\":" + std::to_string(table.size() - 1) + "}");
    auto start = std::chrono::steady_clock::now();
    auto end = start + std::chrono::duration<double>(s.duration);
    auto next_joints = start, next_tf = start, next_image = start, next_info = start;
    while (std::chrono::steady_clock::now() < end)
    {
        auto now = std::chrono::steady_clock::now();
        serve();
        step(now);
        if (now >= next_joints)
        {
            sen::JointState_ js;
            js.header().stamp(now_stamp());
            js.header().frame_id("base_link");
            js.name(names);
            js.position(std::vector<double>(q.begin(), q.end()));
            js.velocity(std::vector<double>(qd.begin(), qd.end()));
            joints_w->write(&js);
            next_joints += std::chrono::milliseconds(10);
        }
        if (now >= next_tf)
        {
            // While it moves: where it last stood (handeye reads the flange once the arm rests).
            tf2::TFMessage_ msg;
            geo::TransformStamped_ t;
            t.header().stamp(now_stamp());
            t.header().frame_id("base_link");
            t.child_frame_id("tool0");
            t.transform(at->flange);
            msg.transforms().push_back(t);
            tf_w->write(&msg);
            next_tf += std::chrono::milliseconds(20);
        }
        if (now >= next_image)
        {
            image.header().stamp(now_stamp());
            image.data(at->pixels.empty() ? grey : at->pixels);
            image_w->write(&image);
            next_image += std::chrono::microseconds(66667);
        }
        if (now >= next_info)
        {
            info.header().stamp(now_stamp());
            info_w->write(&info);
            next_info += std::chrono::milliseconds(500);
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return 0;
}

