// carousel batch: the catalog, the Kubernetes manifest (parsed by a real YAML parser), a local
// batch going on past a corrupt session, and a Slurm job array on a real single-node cluster
// (Debian's slurmctld, slurmd and munge, started in a temporary folder by tests/batch/
// slurm-cluster) with one task killed (and requeued), then cancelled mid-way, and the batch
// resubmitted: every session ends complete and byte-identical to a local batch run with another
// thread count. A local batch interrupted by Ctrl-C writes its summary and goes on when rerun.
#include "carousel/studio/batch.h"

#include <signal.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <map>
#include <set>
#include <thread>

#include "carousel/core/error.h"
#include "carousel/testing/testing.h"

namespace carousel::studio {
namespace {

using json = nlohmann::json;
using testing::RunShell;
using testing::TempDir;

std::string Quote(const std::filesystem::path& path) { return ShellQuote(path.string()); }

// "s3": the folder of session 3.
std::string SessionName(int i) {
  std::string name = "s";
  name += std::to_string(i);
  return name;
}

std::string Carousel() { return testing::CarouselExecutable() + " --log-level warn"; }

// Under the sanitizers (ten times slower) the first three sessions: the long one and two
// short ones still fill the Slurm array two at a time; the Release build runs all six.
#if defined(CAROUSEL_SANITIZE_BUILD)
constexpr int kSessions = 3;
#else
constexpr int kSessions = 6;
#endif

// kSessions small simulated sessions as captured (nothing processed yet), made once per CTest
// run: four products, two seeds; the first is larger, so that its task runs long enough to be
// cancelled mid-way.
std::filesystem::path CapturedSessions() {
  return testing::SharedFixture("batch-captured", [](const std::filesystem::path& folder) {
    const char* scenes[] = {"shoe", "bottle", "avocado", "duck", "bottle", "shoe"};
    for (int i = 0; i < kSessions; ++i) {
      const std::string size = i == 0 ? "--views 10 --size 480x320" : "--views 6 --size 300x200";
      const testing::ShellResult r =
          RunShell(Carousel() + " sim capture --out " + Quote(folder / SessionName(i)) +
                   " --data " + Quote(testing::SharedDataDir()) + " --scene " + scenes[i] + " " +
                   size + " --seed " + std::to_string(i) + " --product SKU-" + std::to_string(i));
      if (r.code != 0) throw IoError(folder, "sim capture failed: " + r.out);
    }
  });
}

// A copy of the captured sessions in `folder`: their paths.
std::vector<std::filesystem::path> CopySessions(const std::filesystem::path& folder) {
  std::vector<std::filesystem::path> sessions;
  for (int i = 0; i < kSessions; ++i) {
    const std::string name = SessionName(i);
    std::filesystem::create_directories(folder);
    std::filesystem::copy(CapturedSessions() / name, folder / name,
                          std::filesystem::copy_options::recursive);
    sessions.push_back(folder / name);
  }
  return sessions;
}

std::string Joined(const std::vector<std::filesystem::path>& sessions) {
  std::string text;
  for (const auto& s : sessions) {
    text += ' ';
    text += Quote(s);
  }
  return text;
}

json Summary(const std::filesystem::path& batch) {
  return json::parse(testing::ReadBytes(batch / "summary.json")).at("tasks");
}

TEST(BatchTest, CatalogReadsQuotedFieldsAndRelativeFoldersAndNamesBadLines) {
  TempDir dir;
  testing::WriteBytes(dir / "catalog.csv",
                      "SKU,session\n# spring collection\n\nSHOE-1,sessions/shoe\n"
                      "\"BAG, red\",/abs/bag\r\n");
  const std::vector<BatchItem> items = ReadCatalog(dir / "catalog.csv");
  ASSERT_EQ(items.size(), 2u);
  EXPECT_EQ(items[0].sku, "SHOE-1");
  EXPECT_EQ(items[0].session, std::filesystem::absolute(dir / "sessions" / "shoe"));
  EXPECT_EQ(items[1].sku, "BAG, red");
  EXPECT_EQ(items[1].session, "/abs/bag");
  testing::WriteBytes(dir / "twice.csv", "A,one\nB,two\nA,three\n");
  EXPECT_THAT([&] { ReadCatalog(dir / "twice.csv"); },
              ::testing::ThrowsMessage<FormatError>(::testing::AllOf(
                  ::testing::HasSubstr("twice.csv"), ::testing::HasSubstr("line 3"),
                  ::testing::HasSubstr("also on line 1"))));
  testing::WriteBytes(dir / "fields.csv", "A,one\nB\n");
  EXPECT_THAT([&] { ReadCatalog(dir / "fields.csv"); },
              ::testing::ThrowsMessage<FormatError>(::testing::HasSubstr("line 2: expected 2")));
  EXPECT_THROW(ReadCatalog(dir / "missing.csv"), IoError);
}

TEST(BatchTest, KubernetesManifestIsAnIndexedJobAYamlParserReads) {
  TempDir dir;
  const std::vector<BatchItem> items = {{"A", "/studio/sessions/a"},
                                        {"B", "/studio/sessions/b"},
                                        {"C: \"quoted\"", "/studio/archive/c"}};
  BatchJobOptions options;
  options.max_parallel = 2;
  options.cpus_per_task = 4;
  options.memory_mb = 3000;
  options.retries = 3;
  options.image = "registry.example/carousel:1.2";
  options.process_args = {"--faces", "5000"};
  testing::WriteBytes(dir / "job.yaml",
                      KubernetesManifest("/studio/batches/spring", items, options));
  const testing::ShellResult parsed = RunShell(
      "python3 -c 'import json, sys, yaml; print(json.dumps(yaml.safe_load(open(sys.argv[1]))))' " +
      Quote(dir / "job.yaml"));
  ASSERT_EQ(parsed.code, 0) << parsed.out;
  const json job = json::parse(parsed.out);
  EXPECT_EQ(job.at("apiVersion"), "batch/v1");
  EXPECT_EQ(job.at("kind"), "Job");
  const json& spec = job.at("spec");
  EXPECT_EQ(spec.at("completionMode"), "Indexed");
  EXPECT_EQ(spec.at("completions"), 3);
  EXPECT_EQ(spec.at("parallelism"), 2);
  EXPECT_EQ(spec.at("backoffLimitPerIndex"), 3);
  EXPECT_EQ(spec.at("podFailurePolicy").at("rules").at(0).at("onExitCodes").at("values"),
            json::array({64, 65, 74}));
  const json& container = spec.at("template").at("spec").at("containers").at(0);
  EXPECT_EQ(container.at("image"), "registry.example/carousel:1.2");
  EXPECT_EQ(container.at("command"), json::array({"carousel", "--threads", "4", "batch", "task",
                                                  "/studio/batches/spring", "--faces", "5000"}));
  EXPECT_EQ(container.at("resources").at("limits").at("memory"), "3000Mi");
  // One volume holds the batch folder and every session, at their own paths.
  EXPECT_EQ(container.at("volumeMounts").at(0).at("mountPath"), "/studio");
  EXPECT_EQ(spec.at("template").at("spec").at("restartPolicy"), "Never");
}

TEST(BatchTest, LocalBatchGoesOnPastACorruptSessionAndNamesItsError) {
  TempDir dir;
  std::vector<std::filesystem::path> sessions = CopySessions(dir / "sessions");
  sessions.resize(3);
  const auto photo = sessions[1] / "images" / "cam0_stop02.jpg";
  const std::string bytes = testing::ReadBytes(photo);
  testing::WriteBytes(photo, bytes.substr(0, bytes.size() / 4));
  const testing::ShellResult run =
      RunShell(Carousel() + " batch --no-publish --out " + Quote(dir / "batch") + Joined(sessions));
  EXPECT_EQ(run.code, 1) << run.out;
  EXPECT_THAT(run.out, ::testing::HasSubstr("SKU-1  failed"));
  const json summary = Summary(dir / "batch");
  ASSERT_EQ(summary.size(), 3u);
  for (int i : {0, 2}) {
    EXPECT_EQ(summary[i].at("status"), "done") << summary[i];
    EXPECT_GT(summary[i].at("faces").get<int>(), 1000);
    EXPECT_GT(summary[i].at("texture_size").get<int>(), 0);
    EXPECT_GT(summary[i].at("peak_mb").get<double>(), 10.0);
    EXPECT_TRUE(std::filesystem::exists(sessions[i] / "model" / "model.glb"));
  }
  EXPECT_EQ(summary[1].at("sku"), "SKU-1");
  EXPECT_EQ(summary[1].at("status"), "failed");
  EXPECT_EQ(summary[1].at("exit_code"), 65);
  EXPECT_THAT(summary[1].at("error").get<std::string>(),
              ::testing::AllOf(::testing::HasSubstr(photo.string()),
                               ::testing::HasSubstr("truncated JPEG")));
  // The CSV says the same; the damaged photo is still there, untouched.
  const std::string csv = testing::ReadBytes(dir / "batch" / "summary.csv");
  EXPECT_THAT(csv, ::testing::HasSubstr("SKU-1," + sessions[1].string() + ",failed"));
  EXPECT_EQ(testing::ReadBytes(photo), bytes.substr(0, bytes.size() / 4));
  EXPECT_THAT(testing::ReadBytes(sessions[1] / "batch.log"),
              ::testing::HasSubstr("truncated JPEG"));
}

// Ctrl-C (SIGINT to the batch alone, as `kill -INT` sends it) while the first task runs: the
// running task is stopped, the others never start, the summary says so, nothing captured is
// lost, and the same command then goes on to the end.
TEST(BatchTest, LocalBatchInterruptedStopsItsTaskWritesTheSummaryAndGoesOnWhenRerun) {
  TempDir dir;
  std::vector<std::filesystem::path> sessions = CopySessions(dir / "sessions");
  sessions.resize(3);
  const std::string batch =
      Carousel() + " batch --no-publish --jobs 1 --out " + Quote(dir / "batch") + Joined(sessions);
  const std::string log = Quote(sessions[0] / "batch.log");
  const testing::ShellResult run =
      RunShell(batch + " & pid=$!; for i in $(seq 3000); do grep -qs silhouettes " + log +
               " && break; sleep 0.1; done; kill -INT $pid; wait $pid; echo \"exit code $?\"");
  EXPECT_THAT(run.out, ::testing::HasSubstr("exit code 130")) << run.out;
  EXPECT_THAT(run.out, ::testing::HasSubstr("stopping 1 running task, 2 not started"));
  const json summary = Summary(dir / "batch");
  ASSERT_EQ(summary.size(), 3u);
  EXPECT_EQ(summary[0].at("status"), "cancelled") << summary[0];
  EXPECT_EQ(summary[0].at("exit_code"), 130) << summary[0];
  for (int i : {1, 2}) {
    EXPECT_EQ(summary[i].at("status"), "cancelled") << summary[i];
    EXPECT_EQ(summary[i].at("error"), "not started: the batch was interrupted");
    EXPECT_FALSE(std::filesystem::exists(sessions[i] / "batch.log"));
  }
  // The task's process is gone, and every photo is still the one captured.
  const int pid = summary[0].at("pid").get<int>();
  ASSERT_GT(pid, 0);
  EXPECT_NE(::kill(pid, 0), 0) << "task 0 (pid " << pid << ") still runs";
  for (const auto& entry : std::filesystem::directory_iterator(sessions[0] / "images")) {
    const auto original = CapturedSessions() / "s0" / "images" / entry.path().filename();
    EXPECT_TRUE(testing::ReadBytes(entry.path()) == testing::ReadBytes(original)) << entry.path();
  }
  EXPECT_FALSE(std::filesystem::exists(sessions[0] / "model" / "model.glb"));

  const testing::ShellResult again = RunShell(batch);
  EXPECT_EQ(again.code, 0) << again.out;
  const json after = Summary(dir / "batch");
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(after[i].at("status"), "done") << after[i];
    EXPECT_TRUE(std::filesystem::exists(sessions[i] / "model" / "model.glb"));
  }
}

// The job id `carousel batch --slurm` printed on its last line ("job 12").
std::string JobId(const std::string& out) {
  const auto at = out.rfind("\njob ");
  if (at == std::string::npos) return {};
  const std::string rest = out.substr(at + 5);
  return rest.substr(0, rest.find('\n'));
}

// The test's own Slurm cluster, stopped however the test ends.
class SlurmCluster {
 public:
  // Ports of its own (this process's), so that a cluster left behind by a killed run, or
  // another build's test, is never in the way.
  explicit SlurmCluster(const std::filesystem::path& folder) : folder_(folder) {
    const int port = 20000 + 2 * static_cast<int>(::getpid() % 5000);
    const testing::ShellResult r = RunShell("CAROUSEL_SLURM_PORT=" + std::to_string(port) + " " +
                                            Script() + " start " + Quote(folder_));
    started_ = r.code == 0;
    output_ = r.out;
  }
  ~SlurmCluster() { RunShell(Script() + " stop " + Quote(folder_)); }
  SlurmCluster(const SlurmCluster&) = delete;
  SlurmCluster& operator=(const SlurmCluster&) = delete;

  bool started() const { return started_; }
  const std::string& output() const { return output_; }
  // `command` run with this cluster's configuration.
  testing::ShellResult Run(const std::string& command) const {
    return RunShell("SLURM_CONF=" + Quote(folder_ / "slurm.conf") + " " + command);
  }

 private:
  static std::string Script() {
    return Quote(std::filesystem::path(CAROUSEL_SOURCE_DIR) / "tests" / "batch" / "slurm-cluster");
  }
  std::filesystem::path folder_;
  bool started_ = false;
  std::string output_;
};

TEST(BatchTest, SlurmJobArrayRequeuesAKilledTaskSurvivesACancelledOneAndMatchesALocalBatch) {
  TempDir dir;
  const std::vector<std::filesystem::path> local = CopySessions(dir / "local");
  const std::vector<std::filesystem::path> cluster = CopySessions(dir / "cluster");
  SlurmCluster slurm(dir / "slurm");
  ASSERT_TRUE(slurm.started()) << slurm.output();

  // The local batch: one session at a time with both cores' threads.
  const testing::ShellResult here = RunShell(Carousel() + " batch --no-publish --jobs 1 --out " +
                                             Quote(dir / "local-batch") + Joined(local));
  ASSERT_EQ(here.code, 0) << here.out;

  // The cluster: one thread per task, two tasks at once.
  const std::string submit = Carousel() + " batch --slurm --no-publish --max-parallel 2 " +
                             "--cpus-per-task 1 --out " + Quote(dir / "batch") + Joined(cluster);
  const testing::ShellResult first = slurm.Run(submit);
  ASSERT_EQ(first.code, 0) << first.out;
  const std::string job_id = JobId(first.out);
  ASSERT_FALSE(job_id.empty()) << first.out;
  EXPECT_THAT(testing::ReadBytes(dir / "batch" / "job.sbatch"),
              ::testing::AllOf(
                  ::testing::HasSubstr("#SBATCH --array=0-" + std::to_string(kSessions - 1) + "%2"),
                  ::testing::HasSubstr("#SBATCH --requeue")));

  // Task 0 (the largest session), once it is well into its reconstruction: its process killed
  // (a crash, which the job script requeues), then, on its second attempt, cancelled.
  const auto working = [&](int attempt) {
    std::error_code ec;
    if (!std::filesystem::exists(cluster[0] / "batch.log", ec)) return false;
    const std::string log = testing::ReadBytes(cluster[0] / "batch.log");
    const auto at = log.find("attempt " + std::to_string(attempt) + " on");
    return at != std::string::npos && log.find("silhouettes", at) != std::string::npos;
  };
  bool killed = false;
  for (int i = 0; i < 1800 && !killed; ++i) {
    if (working(1)) {
      const json record = json::parse(testing::ReadBytes(dir / "batch" / "results" / "0.json"));
      ASSERT_EQ(record.at("status"), "running") << record;
      ASSERT_EQ(::kill(record.at("pid").get<int>(), SIGKILL), 0);
      killed = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(killed) << "task 0 never ran";
  // Slurm holds a requeued job back for a while (its BeginTime, ~2 minutes); the test's
  // administrator lets it go at once.
  bool pending = false;
  for (int i = 0; i < 600 && !pending; ++i) {
    const testing::ShellResult queue = slurm.Run("squeue -h -r -j " + job_id + " -o '%i %T'");
    pending = queue.out.find(job_id + "_0 PENDING") != std::string::npos;
    if (!pending) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(pending) << "task 0 was not requeued: "
                       << testing::ReadBytes(dir / "batch" / "logs" / "task-0.out");
  const testing::ShellResult release =
      slurm.Run("scontrol update JobId=" + job_id + "_0 StartTime=now");
  ASSERT_EQ(release.code, 0) << release.out;
  bool cancelled = false;
  for (int i = 0; i < 3000 && !cancelled; ++i) {
    const testing::ShellResult queue = slurm.Run("squeue -h -r -j " + job_id + " -o '%i %T'");
    if (queue.out.find(job_id + "_0 RUNNING") != std::string::npos && working(2)) {
      ASSERT_EQ(slurm.Run("scancel " + job_id + "_0").code, 0);
      cancelled = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(cancelled) << "the requeued task 0 never ran";
  EXPECT_THAT(testing::ReadBytes(dir / "batch" / "logs" / "task-0.out"),
              ::testing::HasSubstr("task 0 failed with exit code 137; requeued (restart 1 of 2)"));
  const testing::ShellResult after_cancel =
      slurm.Run(Carousel() + " batch status --wait --timeout 900 " + Quote(dir / "batch"));
  EXPECT_EQ(after_cancel.code, 1) << after_cancel.out;  // not every session is complete
  json summary = Summary(dir / "batch");
  EXPECT_EQ(summary[0].at("status"), "cancelled") << summary[0];
  EXPECT_EQ(summary[0].at("attempt"), 1) << summary[0];
  for (int i = 1; i < kSessions; ++i) EXPECT_EQ(summary[i].at("status"), "done") << summary[i];
  EXPECT_FALSE(std::filesystem::exists(cluster[0] / "model" / "model.glb"));

  // Resubmitted: the cancelled session runs, the others find their stages current.
  const testing::ShellResult second = slurm.Run(submit);
  ASSERT_EQ(second.code, 0) << second.out;
  const std::string second_id = JobId(second.out);
  const testing::ShellResult done =
      slurm.Run(Carousel() + " batch status --wait --timeout 900 " + Quote(dir / "batch"));
  EXPECT_EQ(done.code, 0) << done.out;
  summary = Summary(dir / "batch");
  ASSERT_EQ(summary.size(), static_cast<std::size_t>(kSessions));
  for (int i = 0; i < kSessions; ++i) {
    EXPECT_EQ(summary[i].at("status"), "done") << summary[i];
    EXPECT_EQ(summary[i].at("job"), second_id + "_" + std::to_string(i)) << summary[i];
    EXPECT_EQ(summary[i].at("stages"),
              i == 0 ? "reconstruct ran, texture ran" : "reconstruct current, texture current")
        << summary[i];
  }
  // Per-task logs beside each session: both attempts of the cancelled one.
  const std::string log = testing::ReadBytes(cluster[0] / "batch.log");
  EXPECT_THAT(log, ::testing::HasSubstr("Slurm task " + job_id + "_0"));
  EXPECT_THAT(log, ::testing::HasSubstr("task 0 done"));

  // Every session complete, and the same bytes as the local run.
  for (int i = 0; i < kSessions; ++i) {
    for (const char* file : {"recon/mesh.ply", "model/model.png", "model/model.glb"}) {
      ASSERT_TRUE(std::filesystem::exists(cluster[i] / file)) << cluster[i] / file;
      EXPECT_TRUE(testing::ReadBytes(cluster[i] / file) == testing::ReadBytes(local[i] / file))
          << "session " << i << ": " << file << " differs between Slurm and the local batch";
    }
  }
}

}  // namespace
}  // namespace carousel::studio
