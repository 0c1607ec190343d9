//! Query pools: timestamps (GPU time per pass) and pipeline statistics (fragment
//! and compute shader invocations: the coverage benchmark's evidence that effect
//! work follows the screen area of the virtual content).
#![allow(unsafe_code)]

use super::{vkr, GpuContext, GpuError};
use ash::vk;

/// Counters read from one pipeline-statistics query.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Statistics {
    pub fragment_invocations: u64,
    pub compute_invocations: u64,
}

pub struct QueryPool<'a> {
    ctx: &'a GpuContext,
    pool: vk::QueryPool,
    kind: vk::QueryType,
    count: u32,
}

impl<'a> QueryPool<'a> {
    /// `count` timestamp queries. Errors when the device has no timestamps.
    pub fn timestamps(ctx: &'a GpuContext, count: u32) -> Result<Self, GpuError> {
        if !ctx.has_timestamps() {
            return Err(GpuError::Input { input: "queries", problem: "device has no timestamp support".into() });
        }
        Self::new(ctx, vk::QueryType::TIMESTAMP, vk::QueryPipelineStatisticFlags::empty(), count)
    }

    /// `count` pipeline-statistics queries counting fragment and compute shader
    /// invocations. Errors when the feature is not enabled.
    pub fn statistics(ctx: &'a GpuContext, count: u32) -> Result<Self, GpuError> {
        if !ctx.has_pipeline_statistics() {
            return Err(GpuError::Input {
                input: "queries",
                problem: "device has no pipeline-statistics queries".into(),
            });
        }
        let flags = vk::QueryPipelineStatisticFlags::FRAGMENT_SHADER_INVOCATIONS
            | vk::QueryPipelineStatisticFlags::COMPUTE_SHADER_INVOCATIONS;
        Self::new(ctx, vk::QueryType::PIPELINE_STATISTICS, flags, count)
    }

    fn new(
        ctx: &'a GpuContext,
        kind: vk::QueryType,
        flags: vk::QueryPipelineStatisticFlags,
        count: u32,
    ) -> Result<Self, GpuError> {
        let info = vk::QueryPoolCreateInfo::default().query_type(kind).query_count(count).pipeline_statistics(flags);
        // SAFETY: valid device; the feature behind statistics queries was checked.
        let pool = unsafe { ctx.device.create_query_pool(&info, None) }.map_err(vkr("vkCreateQueryPool"))?;
        Ok(Self { ctx, pool, kind, count })
    }

    /// Reset every query (must be recorded before the first use in a submission).
    pub fn record_reset(&self, cmd: vk::CommandBuffer) {
        // SAFETY: `cmd` is recording outside a render pass; the pool is live.
        unsafe { self.ctx.device.cmd_reset_query_pool(cmd, self.pool, 0, self.count) };
    }

    /// Write timestamp `i` after all prior commands reach `stage`.
    pub fn record_timestamp(&self, cmd: vk::CommandBuffer, stage: vk::PipelineStageFlags, i: u32) {
        if self.kind == vk::QueryType::TIMESTAMP && i < self.count {
            // SAFETY: `cmd` is recording; query `i` exists and was reset.
            unsafe { self.ctx.device.cmd_write_timestamp(cmd, stage, self.pool, i) };
        }
    }

    /// Begin statistics query `i` (end it with `record_end` in the same command buffer).
    pub fn record_begin(&self, cmd: vk::CommandBuffer, i: u32) {
        if self.kind == vk::QueryType::PIPELINE_STATISTICS && i < self.count {
            // SAFETY: `cmd` is recording; query `i` exists, was reset, and is not active.
            unsafe { self.ctx.device.cmd_begin_query(cmd, self.pool, i, vk::QueryControlFlags::empty()) };
        }
    }

    pub fn record_end(&self, cmd: vk::CommandBuffer, i: u32) {
        if self.kind == vk::QueryType::PIPELINE_STATISTICS && i < self.count {
            // SAFETY: query `i` was begun in this command buffer.
            unsafe { self.ctx.device.cmd_end_query(cmd, self.pool, i) };
        }
    }

    /// Timestamp results in milliseconds relative to query 0 (waits for them).
    pub fn timestamps_ms(&self) -> Result<Vec<f64>, GpuError> {
        let period = self.ctx.timestamp_period_ns().unwrap_or(1.0) as f64;
        let mut ticks = vec![0u64; self.count as usize];
        // SAFETY: every query was written by a completed submission (caller waited);
        // WAIT makes the call block otherwise.
        unsafe {
            self.ctx.device.get_query_pool_results(
                self.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(vkr("vkGetQueryPoolResults"))?;
        let t0 = ticks.first().copied().unwrap_or(0);
        Ok(ticks.iter().map(|t| t.saturating_sub(t0) as f64 * period * 1e-6).collect())
    }

    /// Statistics results, one per query (waits for them).
    pub fn statistics_results(&self) -> Result<Vec<Statistics>, GpuError> {
        // Two counters per query, in flag-bit order: fragment (bit 7) before compute (bit 10).
        let mut raw = vec![[0u64; 2]; self.count as usize];
        // SAFETY: as in `timestamps_ms`; each result is two 64-bit counters.
        unsafe {
            self.ctx.device.get_query_pool_results(
                self.pool,
                0,
                &mut raw,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(vkr("vkGetQueryPoolResults"))?;
        Ok(raw.iter().map(|r| Statistics { fragment_invocations: r[0], compute_invocations: r[1] }).collect())
    }
}

impl Drop for QueryPool<'_> {
    fn drop(&mut self) {
        // SAFETY: no pending submission uses the pool (callers wait before reading).
        unsafe { self.ctx.device.destroy_query_pool(self.pool, None) };
    }
}
