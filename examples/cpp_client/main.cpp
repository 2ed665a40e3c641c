// fxis_cpp_client: asks an fxis-shm service for synchronized tuples at times of the caller's
// own clock, checks each image's frame-id stamp, and prints one line per camera.
//
//   fxis_cpp_client [--endpoint tcp://127.0.0.1:5555] [--clock monotonic|realtime|tai|boottime]
//                   [--at NS]... [--cameras a,b] [--exchanges 8] [--timeout-ms 2000]
//                   [--server-key server.key --client-key robot1.key_secret]
//
// Without --at it asks once for "now". Output (one key=value line each, times in ns of --clock):
//   clock ours=CLOCK_REALTIME service=monotonic offset_ns=... round_trip_ns=... exchanges=8
//   tuple asked=<ns|now> t_request=... t_request_service=... skew_ns=... sync=joint
//   frame camera=left kind=synthetic frame_id=41 stamp=41 stamp_ok=yes t_capture=... ...
// Exit status: 0 all well, 1 a synthetic camera's stamp did not match its frame id,
// 2 bad arguments, 3 an error reply, no reply in time, or a malformed reply.
#include <cstdlib>
#include <iostream>
#include <sstream>

#include "fxis_client.hpp"

namespace {

struct Options {
    std::string endpoint = "tcp://127.0.0.1:5555";
    std::string clock = "monotonic";
    std::vector<std::optional<int64_t>> at;
    std::vector<std::string> cameras;
    int exchanges = 8;
    int64_t timeout_ms = 2000;
    std::string server_key, client_key;
};

const char* const USAGE =
    "usage: fxis_cpp_client [--endpoint E] [--clock monotonic|realtime|tai|boottime] [--at NS]...\n"
    "                       [--cameras a,b] [--exchanges N] [--timeout-ms MS]\n"
    "                       [--server-key FILE --client-key FILE]\n";

int usage(const std::string& problem) {
    std::cerr << "fxis_cpp_client: " << problem << "\n" << USAGE;
    return 2;
}

std::vector<std::string> split(const std::string& text, char sep) {
    std::vector<std::string> parts;
    std::stringstream in(text);
    for (std::string part; std::getline(in, part, sep);)
        if (!part.empty()) parts.push_back(part);
    return parts;
}

int64_t integer(const std::string& option, const std::string& text) {
    size_t used = 0;
    long long value = std::stoll(text, &used);
    if (used != text.size()) throw std::invalid_argument(option + " takes an integer, not '" + text + "'");
    return value;
}

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        std::string arg = argv[i];
        if (i + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
        std::string value = argv[++i];
        if (arg == "--endpoint") o.endpoint = value;
        else if (arg == "--clock") o.clock = value;
        else if (arg == "--at") o.at.emplace_back(value == "now" ? std::nullopt : std::optional(integer(arg, value)));
        else if (arg == "--cameras") o.cameras = split(value, ',');
        else if (arg == "--exchanges") o.exchanges = int(integer(arg, value));
        else if (arg == "--timeout-ms") o.timeout_ms = integer(arg, value);
        else if (arg == "--server-key") o.server_key = value;
        else if (arg == "--client-key") o.client_key = value;
        else throw std::invalid_argument("unknown option " + arg);
    }
    if (o.server_key.empty() != o.client_key.empty())
        throw std::invalid_argument("--server-key and --client-key go together");
    if (o.exchanges < 1) throw std::invalid_argument("--exchanges must be at least 1");
    if (o.at.empty()) o.at.emplace_back(std::nullopt);
    return o;
}

}  // namespace

int main(int argc, char** argv) {
    for (int i = 1; i < argc; ++i)
        if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
            std::cout << USAGE;
            return 0;
        }
    Options options;
    fxis::Clock clock;
    std::optional<fxis::Keys> keys;
    try {
        options = parse(argc, argv);
        clock = fxis::Clock::named(options.clock);
        if (!options.server_key.empty()) keys = fxis::Keys::from_files(options.server_key, options.client_key);
    } catch (const std::exception& e) {
        return usage(e.what());
    }

    bool stamps_ok = true;
    try {
        fxis::Client client(options.endpoint, clock, std::chrono::milliseconds(options.timeout_ms),
                            keys ? &*keys : nullptr);
        fxis::Reply status = client.call(fxis::json{{"op", "status"}});
        std::map<std::string, std::string> kinds;
        for (const auto& [name, camera] : status.header.at("cameras").items())
            kinds[name] = camera.value("kind", std::string("?"));

        fxis::ClockOffset offset = client.sync_clock(options.exchanges);
        std::cout << "clock ours=" << clock.name << " service=" << status.header.value("clock", std::string("?"))
                  << " offset_ns=" << offset.offset_ns << " round_trip_ns=" << offset.round_trip_ns
                  << " exchanges=" << offset.exchanges << std::endl;

        for (const std::optional<int64_t>& at : options.at) {
            fxis::Tuple tuple = client.tuple(at, options.cameras);
            std::cout << "tuple asked=" << (at ? std::to_string(*at) : "now") << " t_request=" << tuple.t_request
                      << " t_request_service=" << tuple.t_request_service << " skew_ns=" << tuple.skew_ns
                      << " sync=" << tuple.sync << std::endl;
            for (const fxis::Frame& f : tuple.frames) {
                std::optional<uint64_t> stamp = f.stamp();
                const bool synthetic = kinds[f.camera] == "synthetic";
                const bool ok = stamp && *stamp == uint64_t(f.frame_id);
                if (synthetic && !ok) stamps_ok = false;
                std::string shape;
                for (int64_t n : f.shape) shape += (shape.empty() ? "" : "x") + std::to_string(n);
                std::cout << "frame camera=" << f.camera << " kind=" << kinds[f.camera] << " frame_id=" << f.frame_id
                          << " stamp=" << (stamp ? std::to_string(*stamp) : "none")
                          << " stamp_ok=" << (ok ? "yes" : "no") << " t_capture=" << f.t_capture
                          << " t_capture_service=" << f.t_capture_service
                          << " epsilon_ns=" << tuple.t_request - f.t_capture << " generation=" << f.generation
                          << " shape=" << shape << " dtype=" << f.dtype << std::endl;
            }
        }
    } catch (const fxis::ServiceError& e) {
        std::cerr << "fxis_cpp_client: the service answered " << e.what() << std::endl;
        return 3;
    } catch (const fxis::Timeout& e) {
        std::cerr << "fxis_cpp_client: " << e.what() << " from " << options.endpoint
                  << " (is the service running? with CurveZMQ, are our keys among its clients?)" << std::endl;
        return 3;
    } catch (const std::exception& e) {  // ProtocolError, JSON type errors, ZeroMQ errors
        std::cerr << "fxis_cpp_client: " << e.what() << std::endl;
        return 3;
    }
    if (!stamps_ok) {
        std::cerr << "fxis_cpp_client: a frame's pixels do not carry its frame id" << std::endl;
        return 1;
    }
    return 0;
}
