// carousel batch SESSIONS... | --catalog FILE.csv: many sessions processed as independent tasks,
// here (N `carousel batch task` processes at once) or on a Slurm cluster (an sbatch job array),
// or written as a Kubernetes Indexed Job; carousel batch status DIR: where a batch stands.
// Every task is `carousel process SESSION` run by `carousel batch task DIR --index I`, which
// logs to <session>/batch.log and records what became of it in DIR/results/I.json
// (studio/batch.h), wherever it ran.
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <streambuf>
#include <thread>

#include <nlohmann/json.hpp>

#include "carousel/core/file_util.h"
#include "carousel/core/json.h"
#include "carousel/core/timer.h"
#include "carousel/studio/batch.h"
#include "carousel/studio/session.h"
#include "command.h"

extern char** environ;

namespace carousel::app {
namespace {

using json = nlohmann::json;
using studio::BatchItem;
using studio::BatchRecord;

// The `process` flags a batch hands every task.
struct ProcessFlags {
  bool force = false;
  int faces = 0;  // 0: the session's default
  bool publish = true;

  std::vector<std::string> Args() const {
    std::vector<std::string> args;
    if (force) args.emplace_back("--force");
    if (faces > 0) args.insert(args.end(), {"--faces", std::to_string(faces)});
    if (!publish) args.emplace_back("--no-publish");
    return args;
  }
};

void AddProcessFlags(CLI::App* command, ProcessFlags* flags) {
  command->add_flag("--force", flags->force, "run every stage of every session, current or not");
  command->add_option("--faces", flags->faces, "faces of the optimized meshes (0: the default)")
      ->check(CLI::Range(0, 10'000'000));
  command->add_flag(
      "--no-publish", [flags](std::int64_t) { flags->publish = false; },
      "stop each session after the texture stage");
}

struct BatchArgs {
  std::vector<std::filesystem::path> sessions;
  std::filesystem::path catalog;
  std::filesystem::path out = "batch";
  ProcessFlags process;
  int jobs = 0;                // 0: from the cores and the memory
  int memory_per_session = 0;  // MB; 0: estimated from the photos
  bool slurm = false;
  std::filesystem::path k8s_manifest;
  studio::BatchJobOptions job;
};

struct TaskArgs {
  std::filesystem::path folder;
  int index = -1;
  ProcessFlags process;
};

struct StatusArgs {
  std::filesystem::path folder;
  bool wait = false;
  double timeout = 3600.0;
};

// A stream buffer writing to two others (the task's log and what the record reads).
class TeeBuffer : public std::streambuf {
 public:
  TeeBuffer(std::streambuf* a, std::streambuf* b) : a_(a), b_(b) {}

 protected:
  int overflow(int ch) override {
    if (ch == traits_type::eof()) return traits_type::not_eof(ch);
    a_->sputc(static_cast<char>(ch));
    b_->sputc(static_cast<char>(ch));
    return ch;
  }
  std::streamsize xsputn(const char* text, std::streamsize n) override {
    a_->sputn(text, n);
    b_->sputn(text, n);
    return n;
  }
  int sync() override { return a_->pubsync() | b_->pubsync(); }

 private:
  std::streambuf* a_;
  std::streambuf* b_;
};

std::string Environment(const char* name) {
  const char* value = std::getenv(name);
  return value == nullptr ? std::string() : std::string(value);
}

std::string HostName() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "?";
  return name;
}

// This program, by the path every node of a cluster sees it at.
std::filesystem::path SelfExecutable() {
  std::error_code ec;
  std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw IoError("/proc/self/exe", "cannot find this program: " + ec.message());
  return self;
}

// The text after the first "error: " of `text`, to the end of its line.
std::string FirstError(const std::string& text) {
  const auto at = text.find("error: ");
  if (at == std::string::npos) return {};
  const auto start = at + 7;
  return text.substr(start, text.find('\n', start) - start);
}

// "reconstruct ran, texture current, publish ran" from `carousel process` output.
std::string StagesRun(const std::string& out) {
  std::string stages;
  std::istringstream lines(out);
  std::string line;
  for (const char* stage : {"reconstruct: ", "texture: ", "publish: "}) {
    lines.clear();
    lines.seekg(0);
    while (std::getline(lines, line)) {
      if (line.rfind(stage, 0) != 0) continue;
      const std::string what = line.substr(std::string(stage).size());
      const std::string name(stage, std::string(stage).size() - 2);
      if (what.rfind("current", 0) == 0 || what.rfind("ran", 0) == 0) {
        stages += (stages.empty() ? "" : ", ") + name + (what[0] == 'c' ? " current" : " ran");
        break;
      }
    }
  }
  return stages;
}

void WriteRecord(const std::filesystem::path& folder, const BatchRecord& record) {
  WriteFileAtomic(studio::BatchResultFile(folder, record.task),
                  studio::BatchRecordToJson(record).dump(2) + "\n");
}

// carousel batch task DIR [--index I]: task I of the batch in DIR, in this process.
int RunTask(const TaskArgs& args, Io& io) {
  int index = args.index;
  if (index < 0) {
    for (const char* name : {"SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX"}) {
      const std::string value = Environment(name);
      if (!value.empty()) {
        index = std::stoi(value);
        break;
      }
    }
  }
  CAROUSEL_THROW_IF(index < 0, InvalidArgument,
                    "carousel batch task: --index, $SLURM_ARRAY_TASK_ID or "
                    "$JOB_COMPLETION_INDEX must say which task");
  const std::vector<BatchItem> items = studio::ReadBatchTasks(args.folder);
  CAROUSEL_THROW_IF(index >= static_cast<int>(items.size()), InvalidArgument,
                    "carousel batch task: task " << index << " of a batch of " << items.size());
  const BatchItem& item = items[static_cast<std::size_t>(index)];

  BatchRecord record;
  record.task = index;
  record.sku = item.sku;
  record.session = item.session;
  record.status = "running";
  record.host = HostName();
  record.pid = static_cast<int>(::getpid());
  const std::string restarts = Environment("SLURM_RESTART_COUNT");
  record.attempt = restarts.empty() ? 0 : std::stoi(restarts);
  if (const std::string job = Environment("SLURM_ARRAY_JOB_ID"); !job.empty())
    record.job = job + "_" + std::to_string(index);
  WriteRecord(args.folder, record);

  // The session's own log, or the batch's when the session folder is missing.
  std::filesystem::path log = item.session / "batch.log";
  if (!std::filesystem::is_directory(item.session)) {
    std::filesystem::create_directories(args.folder / "logs");
    log = args.folder / "logs" / ("task-" + std::to_string(index) + ".log");
  }
  std::ofstream log_stream(log, std::ios::app);
  if (!log_stream) throw IoError(log, "cannot write the task's log");
  log_stream << "== " << studio::NowUtc() << " carousel batch task " << index << " (" << item.sku
             << "), attempt " << record.attempt + 1 << " on " << record.host
             << (record.job.empty() ? "" : ", Slurm task " + record.job) << '\n'
             << std::flush;

  std::vector<std::string> words = {"carousel",           "--log-level", "info",
                                    "--log-file",         log.string(),  "process",
                                    item.session.string()};
  const std::vector<std::string> flags = args.process.Args();
  words.insert(words.end(), flags.begin(), flags.end());
  std::vector<const char*> argv;
  argv.reserve(words.size());
  for (const std::string& w : words) argv.push_back(w.c_str());
  std::ostringstream out_text, err_text;
  TeeBuffer out_tee(log_stream.rdbuf(), out_text.rdbuf());
  TeeBuffer err_tee(log_stream.rdbuf(), err_text.rdbuf());
  std::ostream out(&out_tee), err(&err_tee);
  Stopwatch watch;
  const int code = RunCli(static_cast<int>(argv.size()), argv.data(), out, err);
  out.flush();
  err.flush();
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  record.seconds = watch.ElapsedSeconds();
  record.peak_mb = static_cast<double>(usage.ru_maxrss) / 1024.0;
  record.exit_code = code;
  record.status = code == kExitOk ? "done" : "failed";
  record.error = FirstError(err_text.str());
  if (code != kExitOk && record.error.empty()) record.error = "exit code " + std::to_string(code);
  record.stages = StagesRun(out_text.str());
  if (code == kExitOk) studio::ReadModelFigures(&record);
  log_stream << "== " << studio::NowUtc() << " task " << index << ' ' << record.status << " in "
             << record.seconds << " s, peak " << record.peak_mb << " MB (exit code " << code
             << ")\n";
  WriteRecord(args.folder, record);
  io.out << item.sku << ": " << record.status << (record.error.empty() ? "" : ": " + record.error)
         << '\n';
  return code;
}

std::vector<BatchItem> BatchItems(const BatchArgs& args) {
  std::vector<BatchItem> items;
  if (!args.catalog.empty()) items = studio::ReadCatalog(args.catalog);
  for (const std::filesystem::path& session : args.sessions)
    items.push_back(studio::BatchItemForSession(session));
  CAROUSEL_THROW_IF(items.empty(), InvalidArgument,
                    "carousel batch: name session folders or --catalog FILE.csv");
  std::map<std::filesystem::path, std::string> seen;
  for (const BatchItem& item : items) {
    const auto [it, added] = seen.emplace(item.session, item.sku);
    CAROUSEL_THROW_IF(!added, InvalidArgument,
                      "carousel batch: session " << item.session.string() << " is listed twice ("
                                                 << it->second << ", " << item.sku << ")");
  }
  return items;
}

// MemAvailable of /proc/meminfo, MB (0 when unknown).
double AvailableMemoryMb() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  double kb = 0.0;
  std::string unit;
  while (in >> key >> kb >> unit) {
    if (key == "MemAvailable:") return kb / 1024.0;
  }
  return 0.0;
}

// A session's peak memory, MB, from its photos' pixels. Measured (bench/batch-throughput and
// single runs, peak RSS of `carousel process`): 6 x 360x240 photos 121-144 MB, 16 x 1296x864
// 419-568 MB, 16 x 2592x1728 840 MB, 16 x 5184x3456 1,574 MB: ~120 + 85 sqrt(Mpx); with a
// margin, 150 + 90 sqrt(Mpx).
double EstimatedSessionMb(const BatchItem& item) {
  try {
    const studio::Session session = studio::ReadSession(item.session);
    double pixels = 0.0;
    for (const studio::SessionView& view : session.views)
      pixels += static_cast<double>(view.camera_model.width) * view.camera_model.height;
    return 150.0 + 90.0 * std::sqrt(pixels / 1e6);
  } catch (const Error&) {
    return 150.0;  // the task will report what is wrong with the session
  }
}

pid_t SpawnTask(const BatchArgs& args, const std::filesystem::path& folder, int index,
                int threads) {
  std::vector<std::string> words = {
      SelfExecutable().string(), "--threads", std::to_string(threads), "batch", "task",
      folder.string(),           "--index",   std::to_string(index)};
  const std::vector<std::string> flags = args.process.Args();
  words.insert(words.end(), flags.begin(), flags.end());
  std::vector<char*> argv;
  argv.reserve(words.size() + 1);
  for (std::string& w : words) argv.push_back(w.data());
  argv.push_back(nullptr);
  const std::string output =
      (folder / "logs" / ("task-" + std::to_string(index) + ".out")).string();
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 1, output.c_str(), O_WRONLY | O_CREAT | O_APPEND,
                                   0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  pid_t pid = -1;
  const int error = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (error != 0)
    throw IoError(argv[0], std::string("cannot start a batch task: ") + std::strerror(error));
  return pid;
}

// Ctrl-C or SIGTERM during a local batch: no new task starts, the running ones are asked to
// stop (SIGINT: `process` cancels at its next step), and the summary is still written.
volatile std::sig_atomic_t g_batch_interrupt = 0;

extern "C" void OnBatchInterrupt(int signal_number) { g_batch_interrupt = signal_number; }

// The handlers for the duration of a local batch (without SA_RESTART, so that wait4 returns).
class BatchInterruptScope {
 public:
  BatchInterruptScope() {
    g_batch_interrupt = 0;
    struct sigaction action {};
    action.sa_handler = OnBatchInterrupt;
    sigemptyset(&action.sa_mask);
    ::sigaction(SIGINT, &action, &previous_int_);
    ::sigaction(SIGTERM, &action, &previous_term_);
  }
  ~BatchInterruptScope() {
    ::sigaction(SIGINT, &previous_int_, nullptr);
    ::sigaction(SIGTERM, &previous_term_, nullptr);
  }
  BatchInterruptScope(const BatchInterruptScope&) = delete;
  BatchInterruptScope& operator=(const BatchInterruptScope&) = delete;

 private:
  struct sigaction previous_int_ {};
  struct sigaction previous_term_ {};
};

// The sessions N at a time in child processes; every record into the summary.
int RunLocal(const BatchArgs& args, const std::vector<BatchItem>& items, Io& io) {
  const std::filesystem::path folder = std::filesystem::absolute(args.out);
  studio::WriteBatchTasks(folder, items);
  std::filesystem::create_directories(folder / "logs");
  const int count = static_cast<int>(items.size());
  for (int i = 0; i < count; ++i) std::filesystem::remove(studio::BatchResultFile(folder, i));

  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  double per_session = args.memory_per_session;
  if (per_session <= 0)
    for (const BatchItem& item : items)
      per_session = std::max(per_session, EstimatedSessionMb(item));
  int jobs = args.jobs;
  std::string why;
  if (jobs <= 0) {
    const double available = AvailableMemoryMb();
    const int by_memory =
        available > 0 ? std::max(1, static_cast<int>(available * 0.8 / per_session)) : cores;
    jobs = std::min(cores, by_memory);
    why = " (" + std::to_string(cores) + " cores, " + std::to_string(static_cast<int>(available)) +
          " MB available, ~" + std::to_string(static_cast<int>(per_session)) + " MB per session)";
  }
  jobs = std::min(jobs, count);
  const int threads = std::max(1, cores / jobs);
  io.out << "batch: " << count << (count == 1 ? " session, " : " sessions, ") << jobs
         << " at a time" << why << ", " << threads << (threads == 1 ? " thread" : " threads")
         << " each; logs in <session>/batch.log\n"
         << std::flush;

  std::map<pid_t, int> running;
  std::vector<BatchRecord> records(items.size());
  int next = 0;
  int finished = 0;
  Stopwatch watch;
  const BatchInterruptScope interrupt_scope;
  bool stopping = false;
  while ((next < count && !stopping) || !running.empty()) {
    if (g_batch_interrupt != 0 && !stopping) {
      stopping = true;
      io.out << "batch: " << strsignal(g_batch_interrupt) << "; stopping " << running.size()
             << (running.size() == 1 ? " running task" : " running tasks") << ", " << count - next
             << " not started\n"
             << std::flush;
      for (const auto& [child, task] : running) ::kill(child, SIGINT);
    }
    while (next < count && !stopping && static_cast<int>(running.size()) < jobs) {
      running[SpawnTask(args, folder, next, threads)] = next;
      ++next;
    }
    if (running.empty()) continue;
    int status = 0;
    rusage usage{};
    const pid_t pid = ::wait4(-1, &status, 0, &usage);
    if (pid < 0) {
      if (errno == EINTR) continue;
      throw Error(std::string("carousel batch: waiting for the tasks: ") + std::strerror(errno));
    }
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const int task = it->second;
    running.erase(it);
    BatchRecord record = studio::ReadBatchResult(folder, task, items[task]);
    record.peak_mb = std::max(record.peak_mb, static_cast<double>(usage.ru_maxrss) / 1024.0);
    if (stopping && (WIFSIGNALED(status) || WEXITSTATUS(status) == kExitCancelled)) {
      record.status = "cancelled";
      record.exit_code = kExitCancelled;
      record.error = "stopped by the interrupted batch";
    } else if (WIFSIGNALED(status)) {
      record.status = "failed";
      record.exit_code = 128 + WTERMSIG(status);
      record.error = std::string("killed by signal ") + strsignal(WTERMSIG(status));
    } else if (record.status != "done" && record.status != "failed") {
      record.status = "failed";
      record.exit_code = WEXITSTATUS(status);
      record.error = "the task ended (exit code " + std::to_string(record.exit_code) +
                     ") without a record; see " +
                     (folder / "logs" / ("task-" + std::to_string(task) + ".out")).string();
    }
    WriteRecord(folder, record);
    records[task] = record;
    ++finished;
    io.out << '[' << finished << '/' << count << "] " << record.sku << ' ' << record.status;
    if (record.status == "done") {
      io.out << " in " << static_cast<int>(record.seconds * 10) / 10.0 << " s, peak "
             << static_cast<int>(record.peak_mb) << " MB";
    } else {
      io.out << ": " << record.error;
    }
    io.out << '\n' << std::flush;
  }
  for (int task = next; task < count; ++task) {
    BatchRecord& record = records[static_cast<std::size_t>(task)];
    record = studio::ReadBatchResult(folder, task, items[static_cast<std::size_t>(task)]);
    record.status = "cancelled";
    record.error = "not started: the batch was interrupted";
    WriteRecord(folder, record);
  }
  studio::WriteBatchSummary(folder, records);
  io.out << studio::BatchTable(records) << "wall time "
         << static_cast<int>(watch.ElapsedSeconds() * 10) / 10.0
         << " s; summary: " << (folder / "summary.csv").string() << ", "
         << (folder / "summary.json").string() << '\n';
  if (stopping) {
    io.out << "batch interrupted: the same command goes on where it stopped (finished stages are "
              "kept)\n";
    return kExitCancelled;
  }
  const bool all_done = std::all_of(records.begin(), records.end(),
                                    [](const BatchRecord& r) { return r.status == "done"; });
  return all_done ? kExitOk : kExitFailure;
}

// A shell command's exit code and output (stdout and stderr).
std::pair<int, std::string> Shell(const std::string& command) {
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return {-1, "cannot run " + command};
  std::string output;
  char buffer[4096];
  std::size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, n);
  const int status = ::pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

std::string Trimmed(std::string text) {
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  return text;
}

// The Slurm jobs submitted for the batch in `folder`, oldest first.
json ReadJobs(const std::filesystem::path& folder) {
  const std::filesystem::path file = folder / "jobs.json";
  if (!std::filesystem::is_regular_file(file)) return json::array();
  return ParseJsonFile(file);
}

// Task index -> Slurm state ("PENDING", "RUNNING", ...) of `job`'s tasks still queued.
// \throw DeviceError when squeue cannot reach the cluster.
std::map<int, std::string> QueuedTasks(const std::string& job) {
  const auto [code, output] = Shell("squeue -h -r -j " + studio::ShellQuote(job) + " -o '%i|%T'");
  std::map<int, std::string> tasks;
  if (code != 0) {
    // A job Slurm no longer knows (finished long ago) is not an error.
    if (output.find("Invalid job id") != std::string::npos) return tasks;
    throw DeviceError("squeue", Trimmed(output));
  }
  std::istringstream lines(output);
  std::string line;
  while (std::getline(lines, line)) {
    const auto bar = line.find('|');
    const auto underscore = line.find('_');
    if (bar == std::string::npos || underscore == std::string::npos || underscore > bar) continue;
    try {
      tasks[std::stoi(line.substr(underscore + 1, bar - underscore - 1))] = line.substr(bar + 1);
    } catch (const std::exception&) {
      continue;  // a range like 12_[3-5] is expanded by -r; anything else is not ours
    }
  }
  return tasks;
}

// Task index -> (state, exit code) from Slurm's accounting, where it exists (slurmdbd); empty
// when sacct answers that accounting is disabled.
std::map<int, std::pair<std::string, int>> AccountedTasks(const std::string& job) {
  const auto [code, output] =
      Shell("sacct -n -P -X -j " + studio::ShellQuote(job) + " -o JobID,State,ExitCode");
  std::map<int, std::pair<std::string, int>> tasks;
  if (code != 0) return tasks;
  std::istringstream lines(output);
  std::string line;
  while (std::getline(lines, line)) {
    std::vector<std::string> fields;
    std::istringstream parts(line);
    for (std::string f; std::getline(parts, f, '|');) fields.push_back(f);
    const auto underscore = fields.empty() ? std::string::npos : fields[0].find('_');
    if (fields.size() < 3 || underscore == std::string::npos) continue;
    try {
      const int task = std::stoi(fields[0].substr(underscore + 1));
      const std::string state = fields[1].substr(0, fields[1].find(' '));  // "CANCELLED by 0"
      tasks[task] = {state, std::stoi(fields[2].substr(0, fields[2].find(':')))};
    } catch (const std::exception&) {
      continue;  // a pending range like 12_[3-5]
    }
  }
  return tasks;
}

int SubmitSlurm(const BatchArgs& args, const std::vector<BatchItem>& items, Io& io) {
  const std::filesystem::path folder = std::filesystem::absolute(args.out);
  const json jobs = ReadJobs(folder);
  if (!jobs.empty()) {
    const std::string last = jobs.back().at("job").get<std::string>();
    CAROUSEL_THROW_IF(!QueuedTasks(last).empty(), InvalidArgument,
                      "carousel batch: Slurm job "
                          << last << " of " << folder.string()
                          << " is still queued or running; wait for it (carousel batch status "
                          << folder.string() << " --wait) or scancel it first");
  }
  studio::WriteBatchTasks(folder, items);
  std::filesystem::create_directories(folder / "logs");
  studio::BatchJobOptions job = args.job;
  job.executable = SelfExecutable();
  job.process_args = args.process.Args();
  const std::filesystem::path script = folder / "job.sbatch";
  WriteFileAtomic(script, studio::SbatchScript(folder, static_cast<int>(items.size()), job));
  const auto [code, output] = Shell("sbatch --parsable " + studio::ShellQuote(script.string()));
  if (code != 0) throw DeviceError("sbatch", Trimmed(output));
  const std::string id = Trimmed(output.substr(0, output.find(';')));
  if (id.empty() || id.find_first_not_of("0123456789") != std::string::npos)
    throw DeviceError("sbatch", "answered '" + Trimmed(output) + "', not a job id");
  json updated = jobs;
  updated.push_back({{"job", id}, {"submitted_utc", studio::NowUtc()}, {"tasks", items.size()}});
  WriteFileAtomic(folder / "jobs.json", updated.dump(2) + "\n");
  io.out << "submitted Slurm job " << id << ": " << items.size() << " tasks (array 0-"
         << items.size() - 1;
  if (job.max_parallel > 0) io.out << ", at most " << job.max_parallel << " at once";
  io.out << "), logs in <session>/batch.log and " << (folder / "logs").string()
         << "\n  carousel batch status " << folder.string() << '\n';
  io.out << "job " << id << '\n';
  return kExitOk;
}

int WriteKubernetes(const BatchArgs& args, const std::vector<BatchItem>& items, Io& io) {
  const std::filesystem::path folder = std::filesystem::absolute(args.out);
  studio::WriteBatchTasks(folder, items);
  studio::BatchJobOptions job = args.job;
  job.process_args = args.process.Args();
  CreateParentFolder(args.k8s_manifest);
  WriteFileAtomic(args.k8s_manifest, studio::KubernetesManifest(folder, items, job));
  io.out << "wrote " << args.k8s_manifest.string() << ": an Indexed Job of " << items.size()
         << " tasks over " << (folder / "tasks.json").string() << "; kubectl apply -f "
         << args.k8s_manifest.string() << '\n';
  return kExitOk;
}

// Where each task of the batch in `folder` stands: the scheduler's queue for the tasks still
// in it, the tasks' records, the sessions' manifests.
std::vector<BatchRecord> Status(const std::filesystem::path& folder, bool* active) {
  const std::vector<BatchItem> items = studio::ReadBatchTasks(folder);
  const json jobs = ReadJobs(folder);
  std::map<int, std::string> queued;
  std::map<int, std::pair<std::string, int>> accounted;
  std::string job;
  if (!jobs.empty()) {
    job = jobs.back().at("job").get<std::string>();
    queued = QueuedTasks(job);
    accounted = AccountedTasks(job);
  }
  const std::string host = HostName();
  *active = !queued.empty();
  std::vector<BatchRecord> records;
  for (int i = 0; i < static_cast<int>(items.size()); ++i) {
    BatchRecord record = studio::ReadBatchResult(folder, i, items[static_cast<std::size_t>(i)]);
    const bool this_job = !job.empty() && record.job == job + "_" + std::to_string(i);
    if (const auto it = queued.find(i); it != queued.end()) {
      std::string state = it->second;
      std::transform(state.begin(), state.end(), state.begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      // A queued task's record is an earlier attempt's, or an earlier job's.
      if (state != "running" || !this_job) record.error.clear();
      record.status = state;
    } else if (record.status == "running" && job.empty() && record.host == host && record.pid > 0 &&
               ::kill(record.pid, 0) == 0) {
      // A local batch still at work.
    } else if (record.status == "running") {
      // It started and never said how it ended: killed (scancel, a time limit, a lost node).
      record.status = "cancelled";
      record.error = "stopped before it finished (scancel, a time limit or a lost node?)";
      if (const auto a = accounted.find(i); a != accounted.end()) {
        record.error = "Slurm: " + a->second.first;
        if (a->second.first != "CANCELLED") record.status = "failed";
      }
    } else if (!job.empty() && !this_job && record.status != "pending") {
      // An earlier job's record, and this job's task never ran.
      record.status = "cancelled";
      record.error = "job " + job + " ended before this task ran";
    }
    if (record.stages.empty()) {
      try {
        const studio::Session session = studio::ReadSession(record.session);
        for (const auto& [stage, state] : session.stages) {
          if (!record.stages.empty()) record.stages += ", ";
          record.stages += stage;
          record.stages += ' ';
          record.stages += state;
        }
      } catch (const Error&) {
        // No manifest: the record (or its absence) says enough.
      }
    }
    records.push_back(record);
  }
  return records;
}

int RunStatus(const StatusArgs& args, Io& io) {
  const std::filesystem::path folder = std::filesystem::absolute(args.folder);
  bool active = false;
  std::vector<BatchRecord> records = Status(folder, &active);
  Stopwatch watch;
  while (args.wait && active) {
    CAROUSEL_THROW_IF(
        watch.ElapsedSeconds() > args.timeout, Error,
        "carousel batch status: the job is still running after " << args.timeout << " s");
    std::this_thread::sleep_for(std::chrono::seconds(2));
    records = Status(folder, &active);
  }
  studio::WriteBatchSummary(folder, records);
  const json jobs = ReadJobs(folder);
  if (!jobs.empty())
    io.out << "Slurm job " << jobs.back().at("job").get<std::string>()
           << (active ? " (queued or running)" : " (ended)") << '\n';
  io.out << studio::BatchTable(records) << "summary: " << (folder / "summary.csv").string() << '\n';
  const bool trouble = std::any_of(records.begin(), records.end(), [](const BatchRecord& r) {
    return r.status == "failed" || r.status == "cancelled";
  });
  return trouble ? kExitFailure : kExitOk;
}

}  // namespace

void AddBatchCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<BatchArgs>();
  command.add_option("sessions", args->sessions, "session folders");
  command.add_option("--catalog", args->catalog,
                     "a CSV of SKU,session folder lines (relative folders: from the CSV's)");
  command
      .add_option("--out", args->out,
                  "the batch folder: task list, per-task records, summary.csv/.json, job files")
      ->capture_default_str();
  AddProcessFlags(&command, &args->process);
  command
      .add_option("--jobs", args->jobs,
                  "sessions at once on this machine (0: from the cores and the memory)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  command
      .add_option("--memory-per-session", args->memory_per_session,
                  "MB one session needs at its peak, for --jobs 0 (0: estimated from its "
                  "photos)")
      ->check(CLI::Range(0, 1 << 24));
  command.add_flag("--slurm", args->slurm,
                   "submit a Slurm job array instead (one task per session; sessions and the "
                   "batch folder must be at the same path on every node)");
  command
      .add_option("--max-parallel", args->job.max_parallel,
                  "Slurm/Kubernetes: tasks at once (0: as many as the cluster gives)")
      ->check(CLI::Range(0, 100000));
  command
      .add_option("--cpus-per-task", args->job.cpus_per_task,
                  "Slurm/Kubernetes: cores per task (its thread count)")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();
  command
      .add_option("--mem-per-task", args->job.memory_mb,
                  "Slurm/Kubernetes: memory per task, MB (0: not requested)")
      ->check(CLI::Range(0, 1 << 24));
  command
      .add_option("--retries", args->job.retries,
                  "Slurm/Kubernetes: times a task failing for a reason other than bad input is "
                  "requeued")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  command.add_option("--partition", args->job.partition, "Slurm: the partition");
  command.add_option("--time", args->job.time_limit, "Slurm: time limit per task (e.g. 30:00)");
  command.add_option("--job-name", args->job.name, "Slurm/Kubernetes: the job's name")
      ->capture_default_str();
  command.add_option("--k8s-manifest", args->k8s_manifest,
                     "write a Kubernetes Indexed Job running the tasks to this file (nothing "
                     "runs here)");
  command.add_option("--image", args->job.image, "Kubernetes: the container image")
      ->capture_default_str();
  command
      .add_option("--volume-claim", args->job.volume_claim,
                  "Kubernetes: the PersistentVolumeClaim holding the sessions")
      ->capture_default_str();
  dispatch.On(&command, [args](Io& io) {
    const std::vector<BatchItem> items = BatchItems(*args);
    CAROUSEL_THROW_IF(args->slurm && !args->k8s_manifest.empty(), InvalidArgument,
                      "carousel batch: --slurm or --k8s-manifest, not both");
    if (!args->k8s_manifest.empty()) return WriteKubernetes(*args, items, io);
    if (args->slurm) return SubmitSlurm(*args, items, io);
    return RunLocal(*args, items, io);
  });

  auto status = std::make_shared<StatusArgs>();
  CLI::App* status_command = command.add_subcommand(
      "status", "where a batch stands: the Slurm queue, each task's record, the sessions");
  status_command->add_option("folder", status->folder, "the batch folder (--out)")->required();
  status_command->add_flag("--wait", status->wait, "wait until no task is queued or running");
  status_command->add_option("--timeout", status->timeout, "with --wait: give up after this long")
      ->capture_default_str();
  dispatch.On(status_command, [status](Io& io) { return RunStatus(*status, io); });

  auto task = std::make_shared<TaskArgs>();
  CLI::App* task_command = command.add_subcommand(
      "task", "run one task of a batch here (what a local batch, Slurm and Kubernetes run)");
  task_command->add_option("folder", task->folder, "the batch folder")->required();
  task_command->add_option("--index", task->index,
                           "the task (default: $SLURM_ARRAY_TASK_ID or $JOB_COMPLETION_INDEX)");
  AddProcessFlags(task_command, &task->process);
  dispatch.On(task_command, [task](Io& io) { return RunTask(*task, io); });
}

}  // namespace carousel::app
